use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, Dataset, Method, Request};

fn run(d: &Dataset, m: Method, s: &SolverSettings) -> Calibration {
    calibrate(
        d,
        &Request {
            method: m,
            settings: s.clone(),
            gauge: None,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"))
}
fn terr(c: &Calibration, t: &Truth) -> f64 {
    let cam = &c.dataset.cameras[0];
    if std::env::var("ROT").is_ok() {
        return mapping_error_rot(
            &t.intrinsics[0],
            &c.state.intrinsics[0],
            cam.width,
            cam.height,
        );
    }
    mapping_error(
        &t.intrinsics[0],
        &c.state.intrinsics[0],
        cam.width,
        cam.height,
    )
}
fn flex_rate(truth: &Truth) -> f64 {
    let t = truth.target;
    let x = (t.cols as f64 - 1.0) / 2.0 * t.spacing;
    let y = (t.rows as f64 - 1.0) / 2.0 * t.spacing;
    let reach = [x * x, y * y, x * y];
    let d = &truth.deformations;
    let sq: f64 = d
        .windows(2)
        .map(|w| {
            let diff = [w[1].a - w[0].a, w[1].b - w[0].b, w[1].c - w[0].c];
            diff.iter()
                .zip(reach)
                .map(|(c, r)| (c * r).powi(2))
                .sum::<f64>()
        })
        .sum();
    (sq / (3.0 * (d.len() - 1) as f64)).sqrt()
}

fn shuffled(data: &Dataset, seed: u64) -> Dataset {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let n = data.num_frames();
    let mut perm: Vec<usize> = (0..n).collect();
    perm.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let mut out = data.clone();
    for o in &mut out.observations {
        o.frame = perm[o.frame];
    }
    out.frame_ids = (0..n)
        .map(|j| data.frame_ids[perm.iter().position(|&p| p == j).unwrap()])
        .collect();
    out.observations
        .sort_by_key(|o| (o.frame, o.camera, o.corner));
    out
}

#[test]
#[ignore]
fn smooth_probe() {
    let seeds: u64 = std::env::var("SEEDS")
        .map(|s| s.parse().unwrap())
        .unwrap_or(6);
    let scen = std::env::var("SCEN").unwrap_or("stills".into());
    use rayon::prelude::*;
    let rows: Vec<String> = (1..=seeds).into_par_iter().map(|seed| {
        let gen = |bend: f64| {
            let mut g = Generator::new(Preset::Flex, None, seed);
            if scen != "stills" { g.video = true; }
            if scen == "hand-held" { g.noise_px = 0.5; g.min_visible = 0.4; g.spec.distance_m = [3.0, 8.0]; }
            g.bend_scale = bend;
            g.generate()
        };
        let (d, t) = gen(1.0);
        let d = if std::env::var("SHUF").is_ok() { shuffled(&d, seed) } else { d };
        let (d0, _) = gen(0.0);
        let floor = terr(&run(&d0, Method::Standard, &SolverSettings::default()), &t);
        let mut base = SolverSettings::default();
        if std::env::var("BENDAUTO").is_ok() { base.board.bend_sigma_auto = true; }
        let pc = run(&d, Method::Dynamic, &base);
        let plain = terr(&pc, &t);
        // variogram of own bends in reach units
        let tg = d.target;
        let x = (tg.cols as f64 - 1.0) / 2.0 * tg.spacing;
        let y = (tg.rows as f64 - 1.0) / 2.0 * tg.spacing;
        let reach = [x * x, y * y, x * y];
        let b: Vec<[f64; 3]> = pc.state.deformations.iter().map(|p| [p.a * reach[0], p.b * reach[1], p.c * reach[2]]).collect();
        let gam = |k: usize| { let n = b.len() - k; (0..n).map(|j| (0..3).map(|q| (b[j + k][q] - b[j][q]).powi(2)).sum::<f64>()).sum::<f64>() / (3.0 * n as f64) };
        let n = b.len();
        let mean: Vec<f64> = (0..3).map(|q| b.iter().map(|v| v[q]).sum::<f64>() / n as f64).collect();
        let var = b.iter().map(|v| (0..3).map(|q| (v[q] - mean[q]).powi(2)).sum::<f64>()).sum::<f64>() / (3.0 * (n - 1) as f64);
        let (g1, g2) = (gam(1), gam(2));
        let s_est = (g2 - g1).max(0.0).sqrt();
        let est_line = format!("g1 {:.3} g2 {:.3} 2var {:.3} R {:.3} s_est {:.3} s_true {:.3}", g1.sqrt()*1e3, g2.sqrt()*1e3, (2.0*var).sqrt()*1e3, g1/(2.0*var), s_est*1e3, flex_rate(&t)*1e3);
        let sigma = if std::env::var("EST").is_ok() { s_est.max(1e-6) } else { flex_rate(&t) };
        let mut s = base.clone();
        s.board.smoothness_sigma_m = Some(sigma);
        if std::env::var("AUTO").is_ok() { s.board.smoothness_sigma_m = None; s.board.smoothness_auto = true; }
        let sc = run(&d, Method::Dynamic, &s);
        let smooth = terr(&sc, &t);
        let est_line = format!("{est_line} used {:?} warn {:?}", sc.settings.board.smoothness_sigma_m.map(|v| (v*1e6).round()/1e3), sc.warnings.iter().filter(|w| w.contains("smooth")).map(|w| w.chars().take(90).collect::<String>()).collect::<Vec<_>>());
        format!("seed {seed} floor {floor:.4} dyn {plain:.4} smooth {smooth:.4} ratio_dyn {:.3} ratio_smooth {:.3} {est_line}", plain / floor, smooth / floor)
    }).collect();
    for r in rows {
        println!("{r}");
    }
}
