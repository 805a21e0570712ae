//! Several cameras: rig poses, per-camera intrinsics, shared deformation.
use crate::common;
use common::*;
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::solver::problem::Loss;
use deformcal::{Calibration, Dataset, Method, Pose};
use nalgebra::{Rotation3, Vector3};

fn rig_error(estimated: &Pose, truth: &Pose) -> (f64, f64) {
    let d = estimated.compose(&truth.inverse());
    (
        d.rotation_matrix().angle().to_degrees(),
        (estimated.translation_vector() - truth.translation_vector()).norm(),
    )
}

fn check_cameras(c: &Calibration, t: &Truth, max_deg: f64, max_m: f64) {
    for (k, cam) in c.dataset.cameras.iter().enumerate() {
        let e = truth_error_rot(c, t, k);
        assert!(e < 0.4, "{}: mapping error to truth {e}", cam.name);
        assert!(
            (c.state.intrinsics[k].fx() - t.intrinsics[k].fx()).abs() < 3.0,
            "{}: fx",
            cam.name
        );
        if k > 0 {
            let (deg, m) = rig_error(&c.state.camera_poses[k], &t.camera_poses[k]);
            assert!(
                deg < max_deg && m < max_m,
                "{}: rig off by {deg}° and {m} m",
                cam.name
            );
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn stereo_recovers_rig_intrinsics_and_constrains_the_bend_better() {
    let (d, t) = Generator::new(Preset::Stereo, Some(40), 9).generate();
    assert_eq!(d.cameras.len(), 2);
    for m in [Method::Standard, Method::Dynamic, Method::Full] {
        let (d_rigid, t_rigid) = {
            let mut g = Generator::new(Preset::Stereo, Some(40), 9);
            g.bend_scale = if m == Method::Standard { 0.0 } else { 1.0 };
            g.generate()
        };
        let c = run(&d_rigid, m, Loss::Cauchy);
        assert!(c.converged, "{m}");
        check_cameras(&c, &t_rigid, 0.02, 1e-3);
    }
    // The same frames seen by camera 0 alone.
    let mono = Dataset {
        cameras: vec![d.cameras[0].clone()],
        observations: d
            .observations
            .iter()
            .filter(|o| o.camera == 0)
            .copied()
            .collect(),
        ..d.clone()
    };
    for m in [Method::Dynamic, Method::Full] {
        let both = bend_errors(&run(&d, m, Loss::Cauchy), &t);
        let one = bend_errors(&run(&mono, m, Loss::Cauchy), &t);
        let (b, o) = (median(both), median(one));
        assert!(b < 0.8 * o, "{m}: stereo bend error {b} not below mono {o}");
    }
}

#[test]
fn three_cameras_chain_through_the_middle_one() {
    let mut g = Generator::new(Preset::T2, Some(90), 4).with_cameras(3);
    g.bend_scale = 0.0;
    g.min_visible_other = 0.2;
    // Cameras fan out 20° apart: camera 2 never shares a view with camera 0.
    g.rig = (0..3)
        .map(|k| {
            let r0k = Rotation3::from_euler_angles(0.0, (20.0 * k as f64).to_radians(), 0.0);
            let r = r0k.inverse();
            Pose::from_parts(&r, &-(r * Vector3::new(0.3 * k as f64, 0.0, 0.0)))
        })
        .collect();
    let (d, t) = g.generate();
    let seen = |k: usize| -> std::collections::HashSet<usize> {
        d.observations
            .iter()
            .filter(|o| o.camera == k)
            .map(|o| o.frame)
            .collect()
    };
    let (s0, s1, s2) = (seen(0), seen(1), seen(2));
    assert_eq!(
        s0.intersection(&s2).count(),
        0,
        "cameras 0 and 2 must not overlap"
    );
    assert!(s0.intersection(&s1).count() >= 3 && s1.intersection(&s2).count() >= 3);
    let c = run(&d, Method::Standard, Loss::Cauchy);
    check_cameras(&c, &t, 0.05, 3e-3);
}

#[test]
fn a_disconnected_camera_is_named() {
    let (mut d, _) = Generator::new(Preset::Stereo, Some(20), 3).generate();
    // Camera 1 keeps only frames camera 0 does not see.
    let seen0: std::collections::HashSet<usize> = d
        .observations
        .iter()
        .filter(|o| o.camera == 0)
        .map(|o| o.frame)
        .collect();
    d.observations
        .retain(|o| o.camera == 0 || !seen0.contains(&o.frame));
    let (d2, _) = Generator::new(Preset::T2, Some(6), 5).generate();
    let offset = d.num_frames();
    d.frame_ids
        .extend((0..d2.num_frames()).map(|j| 1000 + j as i64));
    d.observations
        .extend(d2.observations.iter().map(|o| deformcal::Observation {
            camera: 1,
            frame: o.frame + offset,
            ..*o
        }));
    let e = deformcal::calibrate(
        &d,
        &deformcal::Request {
            method: Method::Standard,
            settings: Default::default(),
            gauge: None,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("cam1") && e.contains("disconnected"), "{e}");
}

#[test]
fn protocol_reports_every_camera() {
    use deformcal::app::config::{Config, ProtocolConfig};
    use deformcal::app::protocol::prepare;
    use deformcal::app::protocol_report::{camera_key, protocol_csv, summarise};
    let config = Config::parse(
        "[data]\nsynthetic = \"stereo\"\n[reference]\nsynthetic = \"reference\"\ncameras = 2\nimages = 60\n",
        std::path::Path::new("stereo.toml"),
    )
    .unwrap();
    let protocol = ProtocolConfig {
        subsets: 4,
        methods: vec![Method::Standard, Method::Dynamic],
        ..ProtocolConfig::default()
    };
    let setup = prepare(&config, &protocol).unwrap();
    let rows = setup.run(None, &|| {});
    assert!(rows.iter().all(|r| r.ok() && r.cameras.len() == 2));
    let csv = String::from_utf8(protocol_csv(&setup.header, &rows).unwrap()).unwrap();
    assert_eq!(csv.lines().count(), 1 + 4 * 2 * 2);
    let sum = summarise(&setup.header, &rows);
    for k in 0..2 {
        let key = camera_key(&setup.header, k, "truth_mapping_error_rot_px");
        assert!(key.starts_with(&format!("cam{k}/")));
        let mean = |m: Method| sum.methods[m.name()].metrics[&key].mean;
        assert!(mean(Method::Dynamic) < mean(Method::Standard), "camera {k}");
        let test = camera_key(&setup.header, k, "test_rmse_px");
        assert!(sum.methods["dynamic"].metrics[&test].mean < 0.25);
    }
}
