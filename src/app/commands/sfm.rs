//! `deformcal sfm`: structure from motion around a synthetic building with a
//! calibration's intrinsics held, its loop-closure error, and the scene in
//! COLMAP's text format.
use crate::app::config::Config;
use crate::app::fsio::{self, OutputSet};
use crate::app::protocol;
use anyhow::{Context, Result};
use std::path::PathBuf;

/// `deformcal sfm`.
#[derive(clap::Args, Debug)]
pub struct SfmArgs {
    /// The TOML config: its [sfm] section (defaults otherwise) and the true camera
    /// (its synthetic data's truth, or its [reference] set's calibration).
    #[arg(long, short)]
    pub config: PathBuf,
    /// The calibration.json whose first camera's intrinsics to test.
    #[arg(long)]
    pub calibration: PathBuf,
    /// Folder for sfm.json and the COLMAP files (default: the config's output dir + /sfm).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// The files of `sfm`'s result set.
fn sfm_files() -> fsio::Owns {
    Box::new(|n| {
        matches!(
            n,
            "sfm.json"
                | "images.txt"
                | "points3D.txt"
                | "match_pairs.txt"
                | crate::app::exports::COLMAP_FILE
        )
    })
}

/// `deformcal sfm`.
pub fn run_sfm(args: SfmArgs) -> Result<()> {
    use crate::app::calibration_json::CalibrationJson;
    use crate::app::{exports, sfm};
    let config = Config::load(&args.config)?;
    let json = CalibrationJson::load(&args.calibration)?;
    if config.cameras.is_empty() {
        anyhow::bail!("{}: no camera to test", args.config.display());
    }
    let (cam, spec) = (&json.cameras[0], &config.cameras[0]);
    if (cam.width, cam.height) != (spec.width, spec.height) {
        anyhow::bail!(
            "{}: camera `{}` is {}×{} but the config's first camera is {}×{}",
            args.calibration.display(),
            cam.name,
            cam.width,
            cam.height,
            spec.width,
            spec.height
        );
    }
    let dir = args.output.unwrap_or_else(|| config.output_dir.join("sfm"));
    // Staged and locked before the solves, like every result set.
    let set = OutputSet::begin(&dir, sfm_files())?;
    let exp = protocol::sfm_for_config(&config)?;
    let tested = exp
        .run(&cam.intrinsics)
        .with_context(|| format!("structure from motion with {}", args.calibration.display()))?;
    let truth = exp.run(&exp.true_camera)?;
    let mut summary = exp.summary_json(&tested);
    summary["loop_closure_px_true_camera"] = truth.loop_closure_px.into();
    let mut warnings = Vec::new();
    let (images, points) = sfm::colmap_scene(&exp.scene);
    let mut files = vec![
        ("sfm.json", serde_json::to_string_pretty(&summary)?),
        ("images.txt", images),
        ("points3D.txt", points),
        ("match_pairs.txt", sfm::match_pairs(&exp.scene)),
    ];
    if let Some(c) = exports::cameras_txt(&json, &mut warnings) {
        files.push((exports::COLMAP_FILE, c));
    }
    for (name, text) in &files {
        fsio::write_atomic(&set.path().join(name), text.as_bytes())?;
    }
    set.commit()?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "loop-closure error: {:.3} px over {} features of the first image ({} frames); \
         with the true camera: {:.3} px\nwritten: sfm.json and COLMAP's cameras.txt, images.txt, \
         points3D.txt, match_pairs.txt in {}",
        tested.loop_closure_px,
        tested.loop_points,
        exp.scene.num_frames(),
        truth.loop_closure_px,
        dir.display()
    );
    Ok(())
}
