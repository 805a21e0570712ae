//! The observations CSV (docs/conventions.md §5, `camera,frame,corner,u,v`): reading with a
//! message naming the line of every problem, and writing.
use crate::app::fsio::write_atomic;
use crate::error::{Error, Result};
use crate::model::camera::CameraSpec;
use crate::model::dataset::{Dataset, HEADER};
use crate::model::target::Target;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::hash::{BuildHasher, Hasher};
use std::path::Path;

/// Reads an observations CSV; every problem is reported with its line.
pub fn read(path: &Path, target: Target, cameras: Vec<CameraSpec>) -> Result<Dataset> {
    let bytes = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_DATA_BYTES)?;
    parse(&bytes, path, target, cameras)
}

/// A data error at `line` of the file at `path`.
fn data_err(path: &Path, line: u64, message: String) -> Error {
    Error::Data {
        path: path.into(),
        line,
        message,
    }
}

/// A CSV reader past a checked header; refuses empty and binary input.
fn open_reader<'a>(bytes: &'a [u8], path: &Path) -> Result<csv::Reader<&'a [u8]>> {
    if bytes.is_empty() {
        return Err(data_err(
            path,
            1,
            "the file is empty; expected the header camera,frame,corner,u,v".into(),
        ));
    }
    if bytes.contains(&0) {
        return Err(data_err(
            path,
            1,
            "this is a binary file, not an observations CSV".into(),
        ));
    }
    // Editors on Windows start UTF-8 files with a byte-order mark.
    let bytes = bytes.strip_prefix("\u{feff}".as_bytes()).unwrap_or(bytes);
    // Fields are trimmed by `RowContext::parse_record` (`str::trim`, what
    // `Trim::All` does to a string record after an ASCII trim, without its two
    // new records per row).
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::Headers)
        .from_reader(bytes);
    let header = reader
        .headers()
        .map_err(|e| data_err(path, 1, format!("unreadable header: {e}")))?;
    if header.iter().collect::<Vec<_>>() != HEADER {
        return Err(data_err(
            path,
            1,
            format!(
                "bad header `{}`; expected `{}`",
                short(&header.iter().collect::<Vec<_>>().join(",")),
                HEADER.join(",")
            ),
        ));
    }
    Ok(reader)
}

/// One observation row: camera, frame, corner and pixel.
type Keyed = (usize, i64, usize, [f64; 2]);

/// What one record is checked against.
struct RowContext<'a> {
    path: &'a Path,
    target: &'a Target,
    cameras: &'a [CameraSpec],
    names: HashMap<&'a str, usize>,
}

impl RowContext<'_> {
    /// Parses and checks one record (not yet for duplicates) at `line`.
    fn parse_record(&self, raw: &csv::StringRecord, line: u64) -> Result<Keyed> {
        let err = |message: String| data_err(self.path, line, message);
        if raw.len() != HEADER.len() {
            return Err(err(format!(
                "expected 5 fields (camera,frame,corner,u,v), found {}",
                raw.len()
            )));
        }
        let mut record = [""; 5];
        for (f, field) in record.iter_mut().zip(raw) {
            *f = field.trim();
        }
        let camera = *self.names.get(record[0]).ok_or_else(|| {
            err(format!(
                "unknown camera `{}` (the config names: {})",
                short(record[0]),
                self.cameras
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?;
        let frame: i64 = record[1]
            .parse()
            .map_err(|_| err(format!("frame `{}` is not an integer", short(record[1]))))?;
        let corner: usize = record[2].parse().map_err(|_| {
            err(format!(
                "corner `{}` is not a non-negative integer",
                short(record[2])
            ))
        })?;
        let target = self.target;
        if corner >= target.num_corners() {
            return Err(err(format!(
                "corner {corner} is outside the {} × {} board (0..{})",
                target.rows,
                target.cols,
                target.num_corners() - 1
            )));
        }
        let mut uv = [0.0; 2];
        for (k, name) in [(3, "u"), (4, "v")] {
            let v: f64 = record[k]
                .parse()
                .map_err(|_| err(format!("{name} `{}` is not a number", short(record[k]))))?;
            if !v.is_finite() {
                return Err(err(format!("{name} is not finite ({v})")));
            }
            uv[k - 3] = v;
        }
        Ok((camera, frame, corner, uv))
    }
}

/// Parses observations CSV bytes; `path` names the source in messages.
pub fn parse(
    bytes: &[u8],
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
) -> Result<Dataset> {
    let mut reader = open_reader(bytes, path)?;
    let context = RowContext {
        path,
        target: &target,
        cameras: &cameras,
        names: cameras
            .iter()
            .enumerate()
            .map(|(i, c)| (c.name.as_str(), i))
            .collect(),
    };
    let mut seen = HashSet::with_hasher(KeyHash);
    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        let line = reader.position().line() + 1;
        match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(data_err(path, line, format!("unreadable CSV record: {e}"))),
        }
        let line = record.position().map(|p| p.line()).unwrap_or(line);
        let (camera, frame, corner, uv) = context.parse_record(&record, line)?;
        if !seen.insert((camera, frame, corner)) {
            return Err(data_err(
                path,
                line,
                format!(
                    "duplicate observation of camera {}, frame {frame}, corner {corner}",
                    cameras[camera].name
                ),
            ));
        }
        rows.push((camera, frame, corner, uv));
    }
    if rows.is_empty() {
        return Err(data_err(
            path,
            1,
            "the file has a header but no observations".into(),
        ));
    }
    Ok(Dataset::from_keyed(target, cameras, rows))
}

/// A plain multiplicative hash for the (camera, frame, corner) keys of the
/// duplicate check: the default SipHash cost as much as the parsing, and
/// nothing here needs its resistance to chosen keys.
#[derive(Clone, Copy, Default)]
struct KeyHash;

impl BuildHasher for KeyHash {
    type Hasher = KeyHasher;
    fn build_hasher(&self) -> KeyHasher {
        KeyHasher(0)
    }
}

struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        bytes.iter().for_each(|&b| self.write_u64(b.into()));
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }
}

/// Writes the observations CSV atomically, sorted by camera, frame and corner.
pub fn write(dataset: &Dataset, path: &Path) -> Result<()> {
    let d = dataset;
    let mut sorted: BTreeMap<(usize, i64, usize), [f64; 2]> = BTreeMap::new();
    for o in &d.observations {
        sorted.insert((o.camera, d.frame_ids[o.frame], o.corner), o.uv);
    }
    // The csv writer quotes a camera name holding a comma or a quote, so the file
    // reads back as it was written.
    let mut w = csv::Writer::from_writer(Vec::with_capacity(40 * sorted.len() + 32));
    let fail = |e: csv::Error| Error::write(path, std::io::Error::other(e.to_string()));
    w.write_record(HEADER).map_err(fail)?;
    for ((camera, frame, corner), uv) in sorted {
        w.write_record([
            d.cameras[camera].name.clone(),
            frame.to_string(),
            corner.to_string(),
            uv[0].to_string(),
            uv[1].to_string(),
        ])
        .map_err(fail)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| Error::write(path, std::io::Error::other(e.to_string())))?;
    write_atomic(path, &bytes)
}

/// A field cut to a readable length for an error message.
fn short(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::lens::LensModel;

    fn read(text: &str) -> Result<Dataset> {
        let target = Target {
            rows: 3,
            cols: 3,
            spacing: 0.02,
        };
        let cameras = vec![CameraSpec::new("cam 0", 640, 480, LensModel::Radial3)];
        parse(text.as_bytes(), Path::new("o.csv"), target, cameras)
    }

    #[test]
    fn fields_are_trimmed_of_any_whitespace() {
        // ASCII and Unicode whitespace (a no-break space, an ideographic space)
        // around fields, as `str::trim` takes them.
        let clean =
            read("camera,frame,corner,u,v\ncam 0,1,2,10.5,20.25\ncam 0,1,3,11,21\n").unwrap();
        let padded = read(
            " camera , frame,corner ,u,v\n\tcam 0 ,\u{a0}1, 2\u{3000},10.5 , 20.25\ncam 0,1,3,11,21\n",
        )
        .unwrap();
        assert_eq!(padded.observations, clean.observations);
        assert_eq!(padded.frame_ids, clean.frame_ids);
        assert_eq!(clean.observations.len(), 2);
        assert_eq!(clean.observations[0].uv, [10.5, 20.25]);
    }

    #[test]
    fn a_duplicate_is_named_by_its_line() {
        let text = "camera,frame,corner,u,v\ncam 0,1,2,1,1\ncam 0,2,2,1,1\ncam 0,1,2,3,3\n";
        let e = read(text).unwrap_err().to_string();
        assert!(e.contains("line 4") || e.contains(":4"), "{e}");
        assert!(
            e.contains("duplicate observation of camera cam 0, frame 1, corner 2"),
            "{e}"
        );
    }
}
