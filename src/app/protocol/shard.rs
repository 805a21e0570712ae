//! Sharding: a slice of the task grid (`--shard`, Slurm, Kubernetes), the
//! file a shard writes, and the merge of shard files back into one run.
use super::record::{Header, Row};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// `--shard i/N`: the i-th of N disjoint slices of the task grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parses `i/N` with 0 ≤ i < N.
    pub fn parse(s: &str) -> Option<Shard> {
        let (i, n) = s.split_once('/')?;
        let (index, count) = (i.trim().parse().ok()?, n.trim().parse().ok()?);
        (count > 0 && index < count).then_some(Shard { index, count })
    }

    /// `--shard auto`: the shard of a Slurm job array task (`SLURM_ARRAY_TASK_ID`,
    /// `_MIN`, `_MAX`, `_COUNT`, `_STEP`) or of a Kubernetes Indexed Job
    /// (`JOB_COMPLETION_INDEX`, with the Job's completions in `DEFORMCAL_SHARD_COUNT`).
    /// `var` reads an environment variable; returns the shard and where it came from.
    pub fn from_env(var: impl Fn(&str) -> Option<String>) -> Result<(Shard, &'static str)> {
        let number = |name: &str| -> Result<Option<usize>> {
            match var(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    Error::Invalid(format!("--shard auto: {name} is `{v}`, not a number"))
                }),
            }
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            // Without _MAX the range is taken from _MIN and _COUNT; the task must lie in it.
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let count = number("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                Error::Invalid(
                    "--shard auto: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not"
                        .into(),
                )
            })?;
            let max = number("SLURM_ARRAY_TASK_MAX")?.unwrap_or(min + count.max(1) - 1);
            let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1);
            if step != 1 || max + 1 != min + count || id < min {
                return Err(Error::Invalid(format!(
                    "--shard auto: the Slurm array must be one contiguous range such as --array=0-{} \
                     (got tasks {min} to {max}, step {step}, {count} tasks)",
                    count.max(1) - 1
                )));
            }
            if id > max {
                return Err(Error::Invalid(format!(
                    "--shard auto: SLURM_ARRAY_TASK_ID {id} is outside the array's tasks {min} to {max}"
                )));
            }
            return Ok((
                Shard {
                    index: id - min,
                    count,
                },
                "SLURM_ARRAY_TASK_ID",
            ));
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let count = number("DEFORMCAL_SHARD_COUNT")?.ok_or_else(|| {
                Error::Invalid(
                    "--shard auto: JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job) but DEFORMCAL_SHARD_COUNT is not; \
                     set it to the Job's completions"
                        .into(),
                )
            })?;
            if index >= count {
                return Err(Error::Invalid(format!(
                    "--shard auto: JOB_COMPLETION_INDEX {index} is not below DEFORMCAL_SHARD_COUNT {count}"
                )));
            }
            return Ok((Shard { index, count }, "JOB_COMPLETION_INDEX"));
        }
        Err(Error::Invalid(
            "--shard auto: neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor JOB_COMPLETION_INDEX \
             (a Kubernetes Indexed Job) is set; give --shard i/N instead"
                .into(),
        ))
    }

    /// Whether task `t` belongs to this shard (round robin, so shards stay balanced).
    pub fn owns(&self, t: usize) -> bool {
        t % self.count == self.index
    }
}

/// A shard's output file: the header and its rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardFile {
    pub header: Header,
    pub shard: [usize; 2],
    pub rows: Vec<Row>,
}

impl ShardFile {
    /// Refuses a shard file whose header is out of bounds or whose shard is no
    /// slice of a run (index not below count).
    pub fn check(&self) -> Result<()> {
        let [index, count] = self.shard;
        if index >= count {
            return Err(Error::Invalid(format!(
                "shard {index}/{count} is impossible: the index must be below the count"
            )));
        }
        self.header.check()
    }
}

/// Reads and checks a shard file, naming it in any error (see [`parse_shard`]).
pub fn read_shard(path: &std::path::Path) -> Result<ShardFile> {
    let bytes = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_DATA_BYTES)?;
    parse_shard(&bytes, path)
}

/// Parses and checks ([`ShardFile::check`]) the bytes of shard file `path`.
pub fn parse_shard(bytes: &[u8], path: &std::path::Path) -> Result<ShardFile> {
    let file: ShardFile = serde_json::from_slice(bytes).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        line: e.line() as u64,
        message: format!("not a deformcal shard file: {e}"),
    })?;
    file.check().map_err(|e| Error::Config {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(file)
}

/// [`merge_named`] with each shard named by its `i/N`.
pub fn merge(files: Vec<ShardFile>) -> Result<(Header, Vec<Row>)> {
    merge_named(
        files
            .into_iter()
            .map(|f| (format!("shard {}/{}", f.shard[0], f.shard[1]), f))
            .collect(),
    )
}

/// Checks that shard files (with the names to give them in messages) come from
/// one run (same header, data fingerprint included) and together cover every
/// task once; returns the header and the rows in task order.
pub fn merge_named(files: Vec<(String, ShardFile)>) -> Result<(Header, Vec<Row>)> {
    let (first_name, first) = files
        .first()
        .ok_or_else(|| Error::Invalid("no shard files to merge".into()))?;
    let (first_name, header) = (first_name.clone(), first.header.clone());
    let mut count = None;
    let mut slots: Vec<Option<Row>> = Vec::new();
    for (name, f) in files {
        f.check()
            .map_err(|e| Error::Invalid(format!("{name}: {e}")))?;
        if f.header != header {
            let what = if f.header.data != header.data {
                format!("other data ({} vs {})", f.header.data, header.data)
            } else {
                "another run (config or seed differ)".to_string()
            };
            return Err(Error::Invalid(format!(
                "{name} and {first_name} are shards of {what}: merge the shards of one run"
            )));
        }
        match count {
            None => count = Some((f.shard[1], name.clone())),
            Some((n, ref other)) if n != f.shard[1] => {
                return Err(Error::Invalid(format!(
                    "{name} is a shard of {} but {other} one of {n}: merge the shards of one run",
                    f.shard[1]
                )));
            }
            Some(_) => {}
        }
        if slots.is_empty() {
            slots = vec![None; header.tasks()];
        }
        for row in f.rows {
            let Some(t) = header.slot_of(&row) else {
                return Err(Error::Invalid(format!(
                    "{name}: a row (subset {}, method {}{}) lies outside the run",
                    row.subset,
                    row.method,
                    if row.auto { ", auto" } else { "" }
                )));
            };
            if slots[t].is_some() {
                return Err(Error::Invalid(format!(
                    "subset {} × {} appears twice (again in {name})",
                    row.subset, row.method
                )));
            }
            slots[t] = Some(row);
        }
    }
    let missing = slots.iter().filter(|s| s.is_none()).count();
    if missing > 0 {
        return Err(Error::Invalid(format!(
            "{missing} of {} subset × method results are missing: merge every shard of the run",
            slots.len()
        )));
    }
    Ok((
        header,
        slots.into_iter().map(|s| s.expect("checked")).collect(),
    ))
}
