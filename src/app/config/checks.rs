//! The config's structure: which data source, board, cameras and reference it
//! describes, and whether they fit together; every message names its key, and its
//! line where the key is in the file. Value ranges are in [`super::limits`].
use super::calibration::apply_bend_order;
use super::checked::{Config, DataSource, ReferenceConfig, DEFAULT_SYNTHETIC_SEED};
use super::checker::Checker;
use super::raw::{PhotoPatterns, RawConfig, RawData, RawReference, RawTarget};
use crate::error::Result;
use crate::model::camera::CameraSpec;
use crate::model::synthetic::{Preset, MAX_IMAGES};
use crate::model::target::Target;
use std::path::PathBuf;

impl Checker<'_> {
    /// The whole config: its data source, rig, reference, settings and output.
    pub(super) fn check(&self, mut raw: RawConfig) -> Result<Config> {
        if let Some(t) = &raw.target {
            t.check().map_err(|m| self.err(m))?;
        }
        let data = self.data_source(&raw.data)?;
        let (target, cameras) = self.rig(&data, &raw)?;
        self.check_target("target", &target)?;
        self.check_camera_names(&cameras)?;
        self.check_camera_params(&cameras)?;
        let reference = self.reference(raw.reference.take(), target)?;
        self.check_calibration(&raw.calibration, &target)?;
        self.check_solver_limits(&raw.calibration)?;
        self.check_board_priors(&raw.calibration)?;
        if let Some(path) = raw.target.as_ref().and_then(|t| t.geometry.clone()) {
            let path = self.base.join(path);
            let g = crate::app::board_json::read(&path, &target)?;
            raw.calibration.geometry = Some(std::sync::Arc::new(g));
        }
        apply_bend_order(&mut raw.calibration, raw.protocol.as_mut());
        if let Some(p) = &raw.protocol {
            self.check_protocol(p)?;
        }
        if let Some(s) = &raw.sfm {
            s.check().map_err(|m| self.err(m))?;
        }
        self.check_camera_patterns(&data, &cameras)?;
        if let DataSource::Photos { patterns, .. } = &data {
            self.check_photo_cameras(patterns, &cameras)?;
        }
        if matches!(data, DataSource::Video(_)) && cameras.len() != 1 {
            return Err(self.err(format!(
                "data.video is one camera's video, but [[cameras]] has {}",
                cameras.len()
            )));
        }
        let output_dir = crate::app::fsio::tidy_path(&match raw.output {
            Some(o) => self.base.join(o.dir),
            None => self.base.join("out"),
        });
        Ok(Config {
            path: self.path.into(),
            target,
            charuco: raw.target.as_ref().and_then(RawTarget::charuco),
            cameras,
            data,
            reference,
            calibration: raw.calibration,
            protocol: raw.protocol,
            sfm: raw.sfm,
            output_dir,
        })
    }

    /// `[data]`: exactly one of photos, corners_vnl, observations and synthetic.
    fn data_source(&self, data: &RawData) -> Result<DataSource> {
        if data.photos.is_some() {
            return self.photos(data);
        }
        if data.video.is_some() || data.stride.is_some() || data.max_frames.is_some() {
            return self.video(data);
        }
        if let Some(vnl) = &data.corners_vnl {
            if data.observations.is_some() || data.synthetic.is_some() {
                return Err(self.err(
                    "[data] takes one of `observations`, `corners_vnl` and `synthetic`".into(),
                ));
            }
            return Ok(DataSource::CornersVnl {
                path: self.base.join(vnl),
                patterns: data.camera_patterns.clone(),
            });
        }
        if !data.camera_patterns.is_empty() {
            return Err(self.err("data.camera_patterns applies to `corners_vnl` only".into()));
        }
        self.source(
            "data",
            data.observations.clone(),
            data.synthetic.clone(),
            data.images,
            data.seed,
            data.cameras,
        )
    }

    /// The board and the cameras: a synthetic preset's, or `[target]` and `[[cameras]]`.
    fn rig(&self, data: &DataSource, raw: &RawConfig) -> Result<(Target, Vec<CameraSpec>)> {
        let target = raw.target.as_ref().map(RawTarget::target);
        if let DataSource::Synthetic {
            preset, cameras: n, ..
        } = data
        {
            return self.synthetic_rig(preset, *n, target.as_ref(), &raw.cameras);
        }
        let t = target.ok_or_else(|| {
            self.err("the config needs a `[target]` section (rows, cols, spacing)".into())
        })?;
        if raw.cameras.is_empty() {
            return Err(self.err("missing [[cameras]]: at least one camera is needed".into()));
        }
        Ok((t, raw.cameras.clone()))
    }

    fn source(
        &self,
        table: &str,
        observations: Option<PathBuf>,
        synthetic: Option<String>,
        images: Option<usize>,
        seed: Option<u64>,
        cameras: Option<usize>,
    ) -> Result<DataSource> {
        match (observations, synthetic) {
            (Some(_), Some(_)) => Err(self.err(format!(
                "[{table}] has both `observations` and `synthetic`; give one"
            ))),
            (None, None) => Err(self.err(format!(
                "[{table}] needs `observations` (a CSV file) or `synthetic` (a preset)"
            ))),
            (Some(p), None) => {
                if images.is_some() || seed.is_some() || cameras.is_some() {
                    return Err(self.err(format!(
                        "{table}.images, {table}.seed and {table}.cameras apply to synthetic data only"
                    )));
                }
                Ok(DataSource::Observations(self.base.join(p)))
            }
            (None, Some(name)) => {
                let preset = Preset::parse(&name).ok_or_else(|| {
                    self.err(format!(
                        "{table}.synthetic: unknown preset `{name}` (expected one of {})",
                        Preset::NAMES.join(", ")
                    ))
                })?;
                if let Some(n) = images.filter(|n| !(1..=MAX_IMAGES).contains(n)) {
                    return Err(self.err(format!(
                        "{table}.images must be 1 to {MAX_IMAGES} (got {n})"
                    )));
                }
                let cameras = cameras.unwrap_or(preset.default_cameras());
                if !(1..=16).contains(&cameras) {
                    return Err(
                        self.err(format!("{table}.cameras must be 1 to 16 (got {cameras})"))
                    );
                }
                Ok(DataSource::Synthetic {
                    preset,
                    images,
                    seed: seed.unwrap_or(DEFAULT_SYNTHETIC_SEED),
                    cameras,
                })
            }
        }
    }

    /// `[data] photos`, which excludes every other source.
    fn photos(&self, data: &RawData) -> Result<DataSource> {
        self.alone_in_data(data, "photos")?;
        let patterns = data.photos.clone().expect("caller checked");
        let all: Vec<&String> = match &patterns {
            PhotoPatterns::One(p) => vec![p],
            PhotoPatterns::PerCamera(m) => m.values().collect(),
        };
        if all.is_empty() || all.iter().any(|p| p.trim().is_empty()) {
            return Err(self.err("data.photos: a pattern must not be empty".into()));
        }
        Ok(DataSource::Photos {
            base: self.base.clone(),
            patterns,
        })
    }

    /// The keys of `[data]` given beside `source` (`photos` or `video`), which
    /// names every one of them: a source that silently won over another would
    /// calibrate data the user did not mean.
    fn alone_in_data(&self, data: &RawData, source: &str) -> Result<()> {
        let given = [
            ("photos", data.photos.is_some()),
            ("video", data.video.is_some()),
            ("stride", source != "video" && data.stride.is_some()),
            ("max_frames", source != "video" && data.max_frames.is_some()),
            ("observations", data.observations.is_some()),
            ("corners_vnl", data.corners_vnl.is_some()),
            ("camera_patterns", !data.camera_patterns.is_empty()),
            ("synthetic", data.synthetic.is_some()),
            ("images", data.images.is_some()),
            ("seed", data.seed.is_some()),
            ("cameras", data.cameras.is_some()),
        ];
        let others: Vec<&str> = given
            .iter()
            .filter(|(key, present)| *present && *key != source)
            .map(|(key, _)| *key)
            .collect();
        if others.is_empty() {
            return Ok(());
        }
        Err(self.err(format!(
            "[data] {source} is a data source of its own; remove {} (given beside it)",
            others
                .iter()
                .map(|k| format!("data.{k}"))
                .collect::<Vec<_>>()
                .join(", ")
        )))
    }

    /// `[data] video` with its `stride` and `max_frames`, which exclude every other source.
    fn video(&self, data: &RawData) -> Result<DataSource> {
        let Some(path) = &data.video else {
            return Err(self.err("data.stride and data.max_frames apply to `video` only".into()));
        };
        self.alone_in_data(data, "video")?;
        if path.as_os_str().is_empty() {
            return Err(self.err("data.video: the file name must not be empty".into()));
        }
        let stride = data.stride.unwrap_or(super::checked::DEFAULT_STRIDE);
        if !(1..=10_000).contains(&stride) {
            return Err(self.err(format!("data.stride must be 1 to 10000, not {stride}")));
        }
        let max_frames = data
            .max_frames
            .unwrap_or(super::checked::DEFAULT_MAX_FRAMES);
        if !(super::checked::MIN_MAX_FRAMES..=MAX_IMAGES).contains(&max_frames) {
            return Err(self.err(format!(
                "data.max_frames must be {} to {MAX_IMAGES}, not {max_frames}",
                super::checked::MIN_MAX_FRAMES
            )));
        }
        Ok(DataSource::Video(super::checked::VideoSource {
            path: self.base.join(path),
            name: path.to_string_lossy().replace('\\', "/"),
            stride,
            max_frames,
        }))
    }

    /// Photo patterns and [[cameras]] must name the same cameras.
    fn check_photo_cameras(&self, patterns: &PhotoPatterns, cameras: &[CameraSpec]) -> Result<()> {
        match patterns {
            PhotoPatterns::One(_) if cameras.len() > 1 => Err(self.err(format!(
                "data.photos: with {} cameras give one pattern per camera, e.g. photos = {{ {} = \"left-*.png\", ... }}",
                cameras.len(),
                cameras[0].name
            ))),
            PhotoPatterns::One(_) => Ok(()),
            PhotoPatterns::PerCamera(m) => {
                if let Some(unknown) = m.keys().find(|k| !cameras.iter().any(|c| &c.name == *k)) {
                    return Err(self.err(format!(
                        "data.photos names `{unknown}`, which is not a camera of [[cameras]]"
                    )));
                }
                match cameras.iter().find(|c| !m.contains_key(&c.name)) {
                    Some(c) => Err(self.err(format!(
                        "data.photos needs a pattern for camera `{}`",
                        c.name
                    ))),
                    None => Ok(()),
                }
            }
        }
    }

    /// A synthetic source's board and cameras; `[target]`/`[[cameras]]` must agree with them.
    fn synthetic_rig(
        &self,
        preset: &Preset,
        n: usize,
        target: Option<&Target>,
        cameras: &[CameraSpec],
    ) -> Result<(Target, Vec<CameraSpec>)> {
        let spec = preset.spec();
        if let Some(t) = target {
            if *t != spec.target {
                return Err(self.err(format!(
                    "[target] differs from the `{}` preset's board ({} × {}, {} m); remove it or use observations",
                    preset.name(), spec.target.rows, spec.target.cols, spec.target.spacing
                )));
            }
        }
        if cameras.is_empty() {
            return Ok((spec.target, preset.cameras(n)));
        }
        if cameras.len() != n {
            return Err(self.err(format!(
                "[[cameras]] lists {} camera(s) but the synthetic rig has {n}; set data.cameras or remove [[cameras]]",
                cameras.len()
            )));
        }
        for (given, simulated) in cameras.iter().zip(preset.cameras(n)) {
            if (given.width, given.height) != (simulated.width, simulated.height) {
                return Err(self.err(format!(
                    "[[cameras]] `{}` differs from the simulated {}×{} camera; only the name, model and fix may be changed",
                    given.name, simulated.width, simulated.height
                )));
            }
        }
        Ok((spec.target, cameras.to_vec()))
    }

    /// `[reference]`: its source, and its board (defaulting to the preset's or the data's).
    fn reference(
        &self,
        raw: Option<RawReference>,
        target: Target,
    ) -> Result<Option<ReferenceConfig>> {
        let Some(r) = raw else {
            return Ok(None);
        };
        let source = self.source(
            "reference",
            r.observations,
            r.synthetic,
            r.images,
            r.seed,
            r.cameras,
        )?;
        let default_target = match &source {
            DataSource::Synthetic { preset, .. } => preset.spec().target,
            _ => target,
        };
        let t = Target {
            rows: r.rows.unwrap_or(default_target.rows),
            cols: r.cols.unwrap_or(default_target.cols),
            spacing: r.spacing.unwrap_or(default_target.spacing),
        };
        self.check_target("reference", &t)?;
        Ok(Some(ReferenceConfig { source, target: t }))
    }

    /// `data.camera_patterns` names only known cameras, and all of them when there are several.
    fn check_camera_patterns(&self, data: &DataSource, cameras: &[CameraSpec]) -> Result<()> {
        if let DataSource::CornersVnl { patterns, .. } = data {
            if let Some(unknown) = patterns
                .keys()
                .find(|k| !cameras.iter().any(|c| &c.name == *k))
            {
                return Err(self.err(format!(
                    "data.camera_patterns names `{unknown}`, which is not a camera of [[cameras]]"
                )));
            }
            if cameras.len() > 1 {
                if let Some(c) = cameras.iter().find(|c| !patterns.contains_key(&c.name)) {
                    return Err(self.err(format!(
                        "data.camera_patterns needs a pattern for camera `{}`",
                        c.name
                    )));
                }
            }
        }
        Ok(())
    }
}
