//! The board-model experiments of issue 15 (beyond the paper), each printed as a
//! table. `cargo bench --bench board -- <experiment>` with `prior` (the 50 × 25
//! protocol on T1–T4 and a rigid board: no prior, `static_prior_mm` of `PRIOR`
//! mm, `"auto"`, and with `bend_prior_mm = "auto"` too; `PRIORS=0,2` picks rows),
//! `reference` (the time of `static_prior_mm = "auto"` on the 650-image
//! reference; not in `all`), `size` (the static prior against the number of
//! images on a rigid board; not in `all`), `gauge` (the static prior against
//! a gauge-invariant one, emulated; not in `all`),
//! `t4` (why `static` loses on T4: the protocol with one change at a time; not in
//! `all`),
//! `order` (the `warped` preset: bend orders 2–4), `auto` (`bend_order = "auto"`
//! on `warped` and T1–T4), `video` (the `flex`
//! preset as stills, as a video and as a hand-held video: temporal smoothness in
//! time order and shuffled), `geometry` (a board measured on the 650-image
//! reference loaded into 25-image `standard` and `static` calibrations) or `all`;
//! `SUBSETS=n` shortens the protocol runs; `VIDEO_SEEDS=n` sets the video seeds (3).
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::prepare;
use deformcal::model::board::{BoardGeometry, Method};
use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::solver::auto_prior;
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, Dataset, Request};
use rayon::prelude::*;
use std::path::Path;
use std::sync::Arc;

fn subsets() -> usize {
    std::env::var("SUBSETS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50)
}

/// Mean truth mapping error per method of a protocol run on `preset` (bend scaled).
fn protocol(preset: &str, extra: &str, bend_scale: f64) -> Vec<(Method, f64, f64, usize)> {
    summarise(&protocol_rows(preset, extra, &|g| {
        g.bend_scale = bend_scale
    }))
}

/// The protocol's rows on `preset` as `vary` changes its generator.
fn protocol_rows(
    preset: &str,
    extra: &str,
    vary: &dyn Fn(&mut Generator),
) -> Vec<deformcal::app::protocol::Row> {
    let text = format!("[data]\nsynthetic = \"{preset}\"\n[calibration]\n{extra}\n");
    let config = Config::parse(&text, Path::new("bench.toml")).expect("bench config");
    let p = ProtocolConfig {
        subsets: subsets(),
        ..ProtocolConfig::default()
    };
    let mut setup = prepare(&config, &p).expect("setup");
    let base = Generator::new(Preset::parse(preset).unwrap(), None, 1);
    let mut g = base.clone();
    vary(&mut g);
    if g != base {
        setup.dataset = g.generate().0;
    }
    setup.run(None, &|| {})
}

/// The four methods' mean ± std, then static/standard and full/dynamic, as table cells.
fn method_cells(r: &[(Method, f64, f64, usize)]) -> String {
    let cells: Vec<String> = r
        .iter()
        .map(|m| format!("{:.3} ± {:.3}", m.1, m.2))
        .collect();
    format!(
        "{} | {:.2} | {:.2}",
        cells.join(" | "),
        r[1].1 / r[0].1,
        r[3].1 / r[2].1
    )
}

/// Mean and standard deviation of the truth mapping error per method.
fn summarise(rows: &[deformcal::app::protocol::Row]) -> Vec<(Method, f64, f64, usize)> {
    Method::ALL
        .iter()
        .map(|&m| {
            let e: Vec<f64> = rows
                .iter()
                .filter(|r| r.method == m && r.ok())
                .filter_map(|r| r.cameras[0].truth_mapping_error_px)
                .collect();
            let n = e.len() as f64;
            let mean = e.iter().sum::<f64>() / n;
            let std = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            (m, mean, std, e.len())
        })
        .collect()
}

fn prior() {
    let prior = std::env::var("PRIOR").unwrap_or_else(|_| "0.05".into());
    let auto = "static_prior_mm = \"auto\"".to_string();
    let configs = [
        ("none", String::new()),
        (
            &*format!("static {prior} mm"),
            format!("static_prior_mm = {prior}"),
        ),
        ("static auto", auto.clone()),
        (
            "static + bend auto",
            format!("{auto}\nbend_prior_mm = \"auto\""),
        ),
    ]
    .map(|(a, b)| (a.to_string(), b));
    let only = std::env::var("PRIORS").ok();
    println!(
        "## board priors: truth mapping error (px), {} × 25 protocol",
        subsets()
    );
    println!(
        "| target | prior | standard | static | dynamic | full | static/standard | full/dynamic |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (name, preset, scale) in [
        ("T1", "t1", 1.0),
        ("T2", "t2", 1.0),
        ("T3", "t3", 1.0),
        ("T4", "t4", 1.0),
        ("rigid (T2 board, no bend)", "t2", 0.0),
    ] {
        for (label, extra) in &configs {
            // `PRIORS=0,2,3` runs only those rows of each target.
            let index = configs.iter().position(|c| &c.0 == label).unwrap_or(0);
            if only
                .as_deref()
                .is_some_and(|o| !o.split(',').any(|i| i == index.to_string()))
            {
                continue;
            }
            let start = std::time::Instant::now();
            let r = protocol(preset, extra, scale);
            println!("| {name} | {label} | {} |", method_cells(&r));
            eprintln!("{name} {label}: {:.0} s", start.elapsed().as_secs_f64());
        }
    }
}

/// `static_prior_mm = "auto"` on the protocol's 650-image reference set
/// (`static`): the calibration's time with and without it, and the estimate's.
fn reference_timing() {
    use deformcal::solver::auto_prior::AutoPrior;
    let (reference, truth) = Generator::new(Preset::Reference, None, 1).generate();
    let plain = SolverSettings::default();
    let mut auto = SolverSettings::default();
    auto.board.static_sigma_auto = true;
    let t = std::time::Instant::now();
    let free = run(&reference, Method::Static, &plain);
    let t_free = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let with = run(&reference, Method::Static, &auto);
    let t_auto = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let noise = with.settings.board.noise_px.expect("a noise");
    let e = AutoPrior::Static.estimate(&free.problem(), &free.state, &free.settings, noise);
    let t_estimate = t.elapsed().as_secs_f64();
    let mut fixed = SolverSettings::default();
    fixed.board.static_sigma_m = Some(0.05e-3);
    let fixed = run(&reference, Method::Static, &fixed);
    println!("## static_prior_mm = \"auto\" on the 650-image reference (`static`)");
    println!(
        "calibration {t_free:.1} s without, {t_auto:.1} s with (estimate alone {t_estimate:.2} s); σ {:.4} mm over {} values; mapping error {:.3} px without, {:.3} px with, {:.3} px with 0.05 mm",
        e.map_or(f64::NAN, |e| e.sigma * 1e3),
        e.map_or(0, |e| e.values),
        truth_error(&free, &truth),
        truth_error(&with, &truth),
        truth_error(&fixed, &truth)
    );
}

/// The static prior against the number of images: rigid T2 boards (the
/// presets' print error), `static` and `full` without a prior, with 0.05 mm
/// and with "auto"; mean truth mapping error over `SUBSETS` (≤ 5) seeds.
fn size() {
    let seeds: Vec<u64> = (1..=subsets().min(5) as u64).collect();
    println!(
        "## static prior against the number of images (rigid T2 board, seeds {seeds:?}): truth mapping error (px)"
    );
    println!("| images | standard | static | static 0.05 mm | static auto | full | full 0.05 mm | full auto | σ auto (static, full) mm |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut fixed = SolverSettings::default();
    fixed.board.static_sigma_m = Some(0.05e-3);
    let mut auto = SolverSettings::default();
    auto.board.static_sigma_auto = true;
    let plain = SolverSettings::default();
    for images in [25, 50, 100, 200, 400] {
        let rows: Vec<Vec<f64>> = seeds
            .par_iter()
            .map(|&seed| {
                let mut g = Generator::new(Preset::T2, Some(images), seed);
                g.bend_scale = 0.0;
                let (data, truth) = g.generate();
                let mut out = vec![truth_error(&run(&data, Method::Standard, &plain), &truth)];
                let mut sigmas = Vec::new();
                for m in [Method::Static, Method::Full] {
                    for s in [&plain, &fixed, &auto] {
                        let c = run(&data, m, s);
                        out.push(truth_error(&c, &truth));
                        if s.board.static_sigma_auto {
                            sigmas.push(c.settings.board.static_sigma_m.unwrap_or(f64::NAN));
                        }
                    }
                }
                out.extend(sigmas);
                out
            })
            .collect();
        let mean = |i: usize| rows.iter().map(|r| r[i]).sum::<f64>() / rows.len() as f64;
        println!(
            "| {images} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.4}, {:.4} |",
            mean(0),
            mean(1),
            mean(2),
            mean(3),
            mean(4),
            mean(5),
            mean(6),
            mean(7) * 1e3,
            mean(8) * 1e3
        );
    }
}

/// The similarity directions (translation, rotation, scale; in-plane for a
/// 2-value correction) as columns over every corner's `dims` correction values.
fn similarity_basis(t: &deformcal::model::target::Target, dims: usize) -> nalgebra::DMatrix<f64> {
    use nalgebra::Vector3;
    let (e0, e1, e2) = (Vector3::x(), Vector3::y(), Vector3::z());
    let n = t.num_corners();
    let mut b = nalgebra::DMatrix::zeros(dims * n, if dims == 3 { 7 } else { 4 });
    for i in 0..n {
        let x = t.nominal(i);
        let columns = if dims == 3 {
            vec![e0, e1, e2, e0.cross(&x), e1.cross(&x), e2.cross(&x), x]
        } else {
            vec![e0, e1, e2.cross(&x), x]
        };
        for (c, v) in columns.iter().enumerate() {
            for k in 0..dims {
                b[(dims * i + k, c)] = v[k];
            }
        }
    }
    b
}

/// `free`'s method (solved without a prior) with a static prior of σ on the
/// correction less its similarity part (gauge-invariant), emulated: the
/// prior's mean is the similarity part of the last solve's correction (zero on
/// the gauge's held values), set as `[target] geometry`, and the solve repeated
/// three times from the free one (from a solve with the i.i.d. prior, whose
/// similarity part that prior has shrunk, the alternation crawls).
fn gauge_invariant(data: &Dataset, free: &Calibration, sigma: f64) -> Calibration {
    let (t, dims) = (data.target, free.method.correction_dims());
    let q = similarity_basis(&t, dims).qr().q();
    let g = &free.gauge;
    let held = |i: usize, k: usize| g[..2].contains(&i) || (dims == 3 && k == 2 && i == g[2]);
    let mut settings = SolverSettings::default();
    settings.board.static_sigma_m = Some(sigma);
    let mut last = free.clone();
    let mut mean = vec![[0.0; 3]; t.num_corners()];
    for _ in 0..3 {
        let total = nalgebra::DVector::from_iterator(
            dims * t.num_corners(),
            (0..t.num_corners())
                .flat_map(|i| (0..dims).map(move |k| (i, k)))
                .map(|(i, k)| last.state.corrections[i][k] + mean[i][k]),
        );
        let m = &q * (q.transpose() * total);
        for (i, v) in mean.iter_mut().enumerate() {
            for k in 0..dims {
                v[k] = if held(i, k) { 0.0 } else { m[dims * i + k] };
            }
        }
        settings.board.geometry = Some(Arc::new(BoardGeometry {
            target: t,
            correction: mean.clone(),
            correction_std: vec![[sigma; 3]; t.num_corners()],
        }));
        last = run(data, free.method, &settings);
    }
    last
}

/// The static prior as it is (i.i.d. on the correction in the gauge's frame)
/// against a gauge-invariant one (emulated, [`gauge_invariant`]), both with
/// the "auto" σ; sums of the truth mapping error over seeds 1–3.
fn gauge() {
    println!("## i.i.d. against gauge-invariant static prior (σ: \"auto\"), truth mapping error summed over seeds 1–3 (px)");
    println!("| data | images | method | standard | no prior | i.i.d. (auto) | gauge-invariant (auto σ) |");
    println!("|---|---|---|---|---|---|---|");
    let mut auto = SolverSettings::default();
    auto.board.static_sigma_auto = true;
    let plain = SolverSettings::default();
    for (name, preset, bend, images) in [
        ("rigid T2 board", Preset::T2, 0.0, 25),
        ("rigid T2 board", Preset::T2, 0.0, 200),
        ("T1", Preset::T1, 1.0, 25),
        ("T3", Preset::T3, 1.0, 25),
    ] {
        for method in [Method::Static, Method::Full] {
            let rows: Vec<[f64; 4]> = (1..=3u64)
                .into_par_iter()
                .map(|seed| {
                    let mut g = Generator::new(preset, Some(images), seed);
                    g.bend_scale = bend;
                    let (data, truth) = g.generate();
                    let with = run(&data, method, &auto);
                    let free = run(&data, method, &plain);
                    let sigma = with.settings.board.static_sigma_m;
                    let invariant = sigma.map(|s| gauge_invariant(&data, &free, s));
                    [
                        truth_error(&run(&data, Method::Standard, &plain), &truth),
                        truth_error(&free, &truth),
                        truth_error(&with, &truth),
                        invariant.map_or(f64::NAN, |c| truth_error(&c, &truth)),
                    ]
                })
                .collect();
            // NaN: "auto" dropped the prior on a seed, so there is no σ to emulate with.
            let sum = |i: usize| match rows.iter().map(|r| r[i]).sum::<f64>() {
                v if v.is_nan() => "—".to_string(),
                v => format!("{v:.3}"),
            };
            println!(
                "| {name} | {images} | {method} | {} | {} | {} | {} |",
                sum(0),
                sum(1),
                sum(2),
                sum(3)
            );
        }
    }
}

/// Why `static` loses to `standard` on T4: the protocol under one change at a time.
fn t4() {
    let prior = std::env::var("PRIOR").unwrap_or_else(|_| "0.05".into());
    println!(
        "## T4 dissected ({} × 25, static_prior_mm = {prior})",
        subsets()
    );
    println!("| variant | standard | static | dynamic | full | static/standard | full/dynamic |");
    println!("|---|---|---|---|---|---|---|");
    type Vary = Box<dyn Fn(&mut Generator)>;
    let variants: Vec<(&str, String, Vary)> = vec![
        ("as is", String::new(), Box::new(|_| {})),
        ("no bend", String::new(), Box::new(|g| g.bend_scale = 0.0)),
        (
            "no print error",
            String::new(),
            Box::new(|g| g.print_scale = 0.0),
        ),
        (
            "noise 0.15 given",
            "detector_noise_px = 0.15".into(),
            Box::new(|_| {}),
        ),
    ];
    let mut variants = variants;
    for n in std::env::var("NOISES").unwrap_or_default().split(',') {
        if let Ok(v) = n.parse::<f64>() {
            variants.push((
                "noise given",
                format!("detector_noise_px = {v}"),
                Box::new(|_| {}),
            ));
        }
    }
    let only = std::env::var("VARIANT").ok();
    for (name, extra, vary) in &variants {
        if only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let rows = protocol_rows(
            "t4",
            &format!("static_prior_mm = {prior}\n{extra}"),
            vary.as_ref(),
        );
        let rmse = |m: Method| {
            let v: Vec<f64> = rows
                .iter()
                .filter(|r| r.method == m)
                .filter_map(|r| r.rmse_px)
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        let r = summarise(&rows);
        println!(
            "| {name} {extra} (RMSE standard {:.3}, static {:.3}, dynamic {:.3}) | {} |",
            rmse(Method::Standard),
            rmse(Method::Static),
            rmse(Method::Dynamic),
            method_cells(&r)
        );
    }
}

fn run(data: &Dataset, method: Method, settings: &SolverSettings) -> Calibration {
    let request = Request {
        method,
        settings: settings.clone(),
        gauge: None,
    };
    calibrate(data, &request).unwrap_or_else(|e| panic!("{method}: {e}"))
}

fn truth_error(c: &Calibration, truth: &Truth) -> f64 {
    let cam = &c.dataset.cameras[0];
    mapping_error(
        &truth.intrinsics[0],
        &c.state.intrinsics[0],
        cam.width,
        cam.height,
    )
}

/// RMS over frames and corners of the estimated bend's Δz minus the truth's, metres.
fn bend_error(c: &Calibration, truth: &Truth) -> f64 {
    use deformcal::model::board::higher_dz;
    let t = c.dataset.target;
    let mut sq = 0.0;
    let mut n = 0.0;
    for (j, &f) in c.dataset.frame_ids.iter().enumerate() {
        let (d, h) = (c.state.deformations[j], c.state.higher_bends[j]);
        let f = f as usize;
        let (td, th) = (truth.deformations[f], truth.higher_bends[f]);
        for p in t.nominal_points() {
            let e = d.dz(p.x, p.y) + higher_dz(&h, p.x, p.y);
            let g = td.dz(p.x, p.y) + higher_dz(&th, p.x, p.y);
            sq += (e - g).powi(2);
            n += 1.0;
        }
    }
    (sq / n).sqrt()
}

fn order() {
    let seeds: Vec<u64> = (1..=subsets().min(10) as u64).collect();
    println!("## bend order on `warped` (25 images, seeds {seeds:?}): truth mapping error (px)");
    println!("| data | rigid floor | standard | dynamic | dynamic3 | dynamic4 | full4 |");
    println!("|---|---|---|---|---|---|---|");
    for preset in [Preset::Warped, Preset::T2] {
        let rows: Vec<Vec<f64>> = seeds
            .par_iter()
            .map(|&seed| {
                let (data, truth) = Generator::new(preset, Some(25), seed).generate();
                let mut g = Generator::new(preset, Some(25), seed);
                g.bend_scale = 0.0;
                let (rigid, rigid_truth) = g.generate();
                let s = SolverSettings::default();
                let mut out = vec![truth_error(
                    &run(&rigid, Method::Standard, &s),
                    &rigid_truth,
                )];
                for m in [
                    Method::Standard,
                    Method::Dynamic,
                    Method::Dynamic3,
                    Method::Dynamic4,
                    Method::Full4,
                ] {
                    out.push(truth_error(&run(&data, m, &s), &truth));
                }
                out
            })
            .collect();
        let mean = |i: usize| rows.iter().map(|r| r[i]).sum::<f64>() / rows.len() as f64;
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            preset.name(),
            mean(0),
            mean(1),
            mean(2),
            mean(3),
            mean(4),
            mean(5)
        );
    }
}

/// The dataset with its frames in a seeded random order (frame ids permuted).
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

/// The video scenarios: the `flex` preset as stills, as a video (poses moving
/// smoothly), and as a hand-held video (poses moving, noisier detections, the
/// board partly out of view and farther away).
fn video_generator(scenario: &str, seed: u64) -> Generator {
    let mut g = Generator::new(Preset::Flex, None, seed);
    if scenario != "stills" {
        g.video = true;
    }
    if scenario == "hand-held" {
        g.noise_px = 0.5;
        g.min_visible = 0.4;
        g.spec.distance_m = [3.0, 8.0];
    }
    g
}

/// One calibration's errors to the truth: mapping error plain and with the
/// virtual rotation profiled out (px), bend error (m).
#[derive(Clone, Copy)]
struct VideoErrors {
    plain: f64,
    rot: f64,
    bend: f64,
}

fn video_errors(c: &Calibration, truth: &Truth) -> VideoErrors {
    let cam = &c.dataset.cameras[0];
    VideoErrors {
        plain: truth_error(c, truth),
        rot: mapping_error_rot(
            &truth.intrinsics[0],
            &c.state.intrinsics[0],
            cam.width,
            cam.height,
        ),
        bend: bend_error(c, truth),
    }
}

/// Geometric mean change (on → off) in per cent with its standard error, and
/// how many of the pairs the change lowered.
fn mean_change(pairs: &[(f64, f64)]) -> String {
    let logs: Vec<f64> = pairs.iter().map(|(off, on)| (on / off).ln()).collect();
    let n = logs.len() as f64;
    let mean = logs.iter().sum::<f64>() / n;
    let var = logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    let better = logs.iter().filter(|&&l| l < 0.0).count();
    format!(
        "{:+.1} % ± {:.1} ({better}/{})",
        100.0 * (mean.exp() - 1.0),
        100.0 * mean.exp() * (var / n).sqrt(),
        logs.len()
    )
}

fn video() {
    println!("## temporal smoothness on `flex` (200 frames, `dynamic`): σ = the true flex rate (× SMOOTH_SCALE), and \"auto\"");
    println!("per seed: mapping error to the truth (px, plain / rotation-compensated) and bend error (mm RMS), off → σ → auto; the σ \"auto\" chose (mm; - where the order test left the prior off)");
    println!("| scenario | seed | order | order test | true σ | auto σ | plain off, σ, auto | rot off, σ, auto | bend off, σ, auto |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let scale: f64 = std::env::var("SMOOTH_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let count: u64 = std::env::var("VIDEO_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let seeds: Vec<u64> = (1..=count).collect();
    let mut summary = Vec::new();
    for scenario in ["stills", "video", "hand-held"] {
        for label in ["time", "shuffled"] {
            let rows: Vec<(String, [VideoErrors; 3])> = seeds
                .par_iter()
                .map(|&seed| {
                    let (data, truth) = video_generator(scenario, seed).generate();
                    let sigma = truth.flex_rate() * scale;
                    let d = if label == "time" { data } else { shuffled(&data, seed) };
                    let plain = run(&d, Method::Dynamic, &SolverSettings::default());
                    let mut s = SolverSettings::default();
                    s.board.smoothness_sigma_m = Some(sigma);
                    let smooth = run(&d, Method::Dynamic, &s);
                    let mut a = SolverSettings::default();
                    a.board.smoothness_auto = true;
                    let auto = run(&d, Method::Dynamic, &a);
                    let auto_sigma = auto
                        .settings
                        .board
                        .smoothness_sigma_m
                        .map_or("-".to_string(), |v| format!("{:.3}", v * 1e3));
                    let e = [&plain, &smooth, &auto].map(|c| video_errors(c, &truth));
                    let test = auto_prior::frame_bends_at_reach(&plain.problem(), &plain.state)
                        .and_then(|b| auto_prior::order_test(&b))
                        .map_or("-".to_string(), |t| format!("{:.3} (p {:.3})", t.ratio, t.p_value));
                    let line = format!(
                        "| {scenario} | {seed} | {label} | {test} | {:.3} | {auto_sigma} | {:.4}, {:.4}, {:.4} | {:.4}, {:.4}, {:.4} | {:.4}, {:.4}, {:.4} |",
                        sigma * 1e3,
                        e[0].plain, e[1].plain, e[2].plain,
                        e[0].rot, e[1].rot, e[2].rot,
                        e[0].bend * 1e3, e[1].bend * 1e3, e[2].bend * 1e3,
                    );
                    (line, e)
                })
                .collect();
            for (l, _) in &rows {
                println!("{l}");
            }
            let pairs = |on: usize, f: fn(&VideoErrors) -> f64| -> Vec<(f64, f64)> {
                rows.iter().map(|(_, e)| (f(&e[0]), f(&e[on]))).collect()
            };
            let cells: Vec<String> = [1, 2]
                .iter()
                .flat_map(|&on| {
                    [
                        mean_change(&pairs(on, |e| e.rot)),
                        mean_change(&pairs(on, |e| e.plain)),
                        mean_change(&pairs(on, |e| e.bend)),
                    ]
                })
                .collect();
            summary.push(format!("| {scenario} | {label} | {} |", cells.join(" | ")));
        }
    }
    println!("\nchange on → off, geometric mean ± standard error (seeds lowered / seeds), seeds 1–{count}:");
    println!("| scenario | order | σ: rot mapping | σ: plain mapping | σ: bend | auto: rot mapping | auto: plain mapping | auto: bend |");
    println!("|---|---|---|---|---|---|---|---|");
    for l in summary {
        println!("{l}");
    }
}

fn geometry() {
    println!("## a board measured on the 650-image reference, loaded into 25-image `standard`");
    let (reference, _) = Generator::new(Preset::Reference, None, 1).generate();
    let s = SolverSettings::default();
    let measured = run(&reference, Method::Static, &s);
    let json = deformcal::app::board_json::of(&measured).expect("static measures the board");
    let geometry = Arc::new(BoardGeometry {
        target: reference.target,
        correction: json.correction.clone(),
        correction_std: json.correction_std.clone().unwrap_or_default(),
    });
    // T2's board is the reference's: the same seed draws the same print error.
    let (t2, truth) = Generator::new(Preset::T2, None, 1).generate();
    let seeds: Vec<u64> = (1..=subsets() as u64).collect();
    let rows: Vec<[f64; 4]> = seeds
        .par_iter()
        .map(|&seed| {
            use rand::seq::index::sample;
            use rand::SeedableRng;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let mut frames = sample(&mut rng, t2.num_frames(), 25).into_vec();
            frames.sort_unstable();
            let data = t2.subset(&frames);
            let plain = truth_error(&run(&data, Method::Standard, &s), &truth);
            let mut with = s.clone();
            with.board.geometry = Some(geometry.clone());
            // As the nominal board (`standard`: held) and as the prior's mean with
            // its covariance (`static`: re-estimated, held by the measured σ).
            [
                plain,
                truth_error(&run(&data, Method::Standard, &with), &truth),
                truth_error(&run(&data, Method::Static, &s), &truth),
                truth_error(&run(&data, Method::Static, &with), &truth),
            ]
        })
        .collect();
    let n = rows.len() as f64;
    let mean = |i: usize| rows.iter().map(|r| r[i]).sum::<f64>() / n;
    let wins = |i: usize| rows.iter().filter(|r| r[i] < r[0]).count();
    println!("| standard | standard + board.json (nominal) | static | static + board.json (prior mean, covariance) |\n|---|---|---|---|");
    println!(
        "| {:.3} | {:.3} (better in {}/{}) | {:.3} | {:.3} (better than standard in {}/{}) |",
        mean(0),
        mean(1),
        wins(1),
        rows.len(),
        mean(2),
        mean(3),
        wins(3),
        rows.len()
    );
}

fn auto() {
    use deformcal::model::selection::AutoSettings;
    use deformcal::solver::select::calibrate_auto;
    let seeds: Vec<u64> = (1..=subsets().min(10) as u64).collect();
    println!(
        "## bend_order = \"auto\" (method dynamic; 25 images, seeds {seeds:?}): methods chosen"
    );
    println!("| data | standard | dynamic | dynamic3 | dynamic4 |\n|---|---|---|---|---|");
    for preset in [
        Preset::Warped,
        Preset::T1,
        Preset::T2,
        Preset::T3,
        Preset::T4,
    ] {
        let candidates = vec![
            Method::Standard,
            Method::Dynamic,
            Method::Dynamic3,
            Method::Dynamic4,
        ];
        let chosen: Vec<Method> = seeds
            .par_iter()
            .map(|&seed| {
                let (data, _) = Generator::new(preset, Some(25), seed).generate();
                let auto = AutoSettings {
                    candidates: candidates.clone(),
                    ..AutoSettings::default()
                };
                let request = Request {
                    method: Method::Dynamic,
                    settings: SolverSettings::default(),
                    gauge: None,
                };
                calibrate_auto(&data, &request, &auto, &|| {})
                    .expect("auto")
                    .method
            })
            .collect();
        let count = |m: Method| chosen.iter().filter(|&&c| c == m).count();
        println!(
            "| {} | {} | {} | {} | {} |",
            preset.name(),
            count(Method::Standard),
            count(Method::Dynamic),
            count(Method::Dynamic3),
            count(Method::Dynamic4)
        );
    }
}

fn main() {
    let which = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .unwrap_or_else(|| "all".into());
    let all = which == "all";
    if all || which == "prior" {
        prior();
    }
    if which == "t4" {
        t4();
    }
    if which == "reference" {
        reference_timing();
    }
    if which == "size" {
        size();
    }
    if which == "gauge" {
        gauge();
    }
    if all || which == "order" {
        order();
    }
    if all || which == "auto" {
        auto();
    }
    if all || which == "video" {
        video();
    }
    if all || which == "geometry" {
        geometry();
    }
}
