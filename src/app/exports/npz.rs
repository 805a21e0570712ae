//! numpy's file formats, as far as mrcal's `optimization_inputs` need them: `.npy`
//! arrays (little-endian f64, i32, bool and unicode scalars, C order) and the `.npz`
//! container (a zip of `<key>.npy` entries, deflated like `np.savez_compressed`),
//! plus Python's `base64.b85encode`. Pure byte formatting: no numpy at run time.
use flate2::write::DeflateEncoder;
use flate2::Compression;
use std::io::Write;

/// One numpy array: its dtype descriptor, shape and little-endian payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Npy {
    descr: String,
    shape: Vec<usize>,
    data: Vec<u8>,
}

impl Npy {
    /// A float64 array of `shape` from `values` in C (row-major) order.
    pub fn f64(shape: &[usize], values: &[f64]) -> Npy {
        debug_assert_eq!(shape.iter().product::<usize>(), values.len());
        Npy {
            descr: "<f8".into(),
            shape: shape.to_vec(),
            data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    /// An int32 array of `shape` from `values` in C order.
    pub fn i32(shape: &[usize], values: &[i32]) -> Npy {
        debug_assert_eq!(shape.iter().product::<usize>(), values.len());
        Npy {
            descr: "<i4".into(),
            shape: shape.to_vec(),
            data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    /// A float64 scalar (a 0-d array).
    pub fn scalar(v: f64) -> Npy {
        Npy::f64(&[], &[v])
    }

    /// A bool scalar.
    pub fn bool(v: bool) -> Npy {
        Npy {
            descr: "|b1".into(),
            shape: Vec::new(),
            data: vec![u8::from(v)],
        }
    }

    /// A unicode scalar (numpy's `<U n`, UCS-4); the empty string is `<U1`, as
    /// `np.array('')` is.
    pub fn str(s: &str) -> Npy {
        let n = s.chars().count().max(1);
        let mut data: Vec<u8> = s.chars().flat_map(|c| (c as u32).to_le_bytes()).collect();
        data.resize(4 * n, 0);
        Npy {
            descr: format!("<U{n}"),
            shape: Vec::new(),
            data,
        }
    }

    /// The `.npy` file: format 1.0, its header padded to a multiple of 64 bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let dims: Vec<String> = self.shape.iter().map(usize::to_string).collect();
        let shape = match dims.len() {
            1 => format!("({},)", dims[0]),
            _ => format!("({})", dims.join(", ")),
        };
        let mut header = format!(
            "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
            self.descr
        );
        // magic (6) + version (2) + length (2) + header + '\n'
        let unpadded = 10 + header.len() + 1;
        header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend((header.len() as u16).to_le_bytes());
        out.extend(header.as_bytes());
        out.extend(&self.data);
        out
    }
}

/// Why an archive cannot be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the optimization inputs exceed the 4 GiB a zip without Zip64 can hold")]
pub struct TooLarge;

/// An `.npz` archive of `(key, array)` pairs, each stored as `<key>.npy`, deflated.
pub fn npz(entries: &[(&str, Npy)]) -> Result<Vec<u8>, TooLarge> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    // Deflate's fastest level and one encoder for every entry: the default level
    // took most of the time of writing a whole result set for a few per cent of
    // the size, and each new encoder allocates its tables again.
    let mut z = DeflateEncoder::new(Vec::new(), Compression::fast());
    for (key, array) in entries {
        let name = format!("{key}.npy");
        let raw = array.to_bytes();
        z.write_all(&raw).expect("writing to a Vec cannot fail");
        let packed = z.reset(Vec::new()).expect("writing to a Vec cannot fail");
        let entry = ZipEntry {
            name: &name,
            crc: crc32fast::hash(&raw),
            packed: u32::try_from(packed.len()).map_err(|_| TooLarge)?,
            size: u32::try_from(raw.len()).map_err(|_| TooLarge)?,
            offset: u32::try_from(out.len()).map_err(|_| TooLarge)?,
        };
        out.extend(entry.local_header());
        out.extend(&packed);
        central.extend(entry.central_header());
    }
    let count = u16::try_from(entries.len()).map_err(|_| TooLarge)?;
    let central_offset = u32::try_from(out.len()).map_err(|_| TooLarge)?;
    let central_size = u32::try_from(central.len()).map_err(|_| TooLarge)?;
    out.extend(central);
    // End of central directory: one disk, no comment.
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0u8; 4]);
    out.extend(count.to_le_bytes());
    out.extend(count.to_le_bytes());
    out.extend(central_size.to_le_bytes());
    out.extend(central_offset.to_le_bytes());
    out.extend([0u8; 2]);
    Ok(out)
}

/// What the local and the central header of one zip entry share.
struct ZipEntry<'a> {
    name: &'a str,
    crc: u32,
    packed: u32,
    size: u32,
    offset: u32,
}

/// Version 2.0 (deflate), method 8 (deflate), 1980-01-01 00:00.
const ZIP_VERSION: u16 = 20;
const DEFLATE: u16 = 8;
const DOS_DATE_1980: u16 = 0x21;

impl ZipEntry<'_> {
    /// From "version needed" to the extra field's length: the same in both headers.
    fn common(&self) -> Vec<u8> {
        let mut h = Vec::new();
        h.extend(ZIP_VERSION.to_le_bytes());
        h.extend(0u16.to_le_bytes()); // flags
        h.extend(DEFLATE.to_le_bytes());
        h.extend(0u16.to_le_bytes()); // time
        h.extend(DOS_DATE_1980.to_le_bytes());
        h.extend(self.crc.to_le_bytes());
        h.extend(self.packed.to_le_bytes());
        h.extend(self.size.to_le_bytes());
        h.extend((self.name.len() as u16).to_le_bytes());
        h.extend(0u16.to_le_bytes()); // extra field length
        h
    }

    fn local_header(&self) -> Vec<u8> {
        let mut h = 0x0403_4b50u32.to_le_bytes().to_vec();
        h.extend(self.common());
        h.extend(self.name.as_bytes());
        h
    }

    fn central_header(&self) -> Vec<u8> {
        let mut h = 0x0201_4b50u32.to_le_bytes().to_vec();
        h.extend(ZIP_VERSION.to_le_bytes()); // version made by
        h.extend(self.common());
        // Comment length, disk number, internal (2) and external (4) attributes.
        h.extend([0u8; 10]);
        h.extend(self.offset.to_le_bytes());
        h.extend(self.name.as_bytes());
        h
    }
}

/// RFC 1924's alphabet, the one Python's `base64.b85encode` uses.
const B85: &[u8; 85] =
    b"0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~";

/// `base64.b85encode(data)` (without `pad`): each 4 bytes, big-endian, as 5 digits
/// most significant first; a short last group is zero-filled and as many digits cut.
pub fn b85encode(data: &[u8]) -> String {
    let mut out = String::with_capacity(data.len().div_ceil(4) * 5);
    for chunk in data.chunks(4) {
        let mut word = [0u8; 4];
        word[..chunk.len()].copy_from_slice(chunk);
        let mut v = u32::from_be_bytes(word);
        let mut digits = [0u8; 5];
        for d in digits.iter_mut().rev() {
            *d = B85[(v % 85) as usize];
            v /= 85;
        }
        for &d in &digits[..chunk.len() + 1] {
            out.push(d as char);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::read::DeflateDecoder;
    use std::io::Read;

    /// `np.save` of the same arrays, by numpy 1.24 (the bytes after the header
    /// are the payload).
    fn numpy_save(descr: &str, shape: &str, payload: &[u8]) -> Vec<u8> {
        let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        let mut out = b"\x93NUMPY\x01\x00v\x00".to_vec();
        out.extend(format!("{dict:<117}\n").as_bytes());
        out.extend(payload);
        out
    }

    #[test]
    fn arrays_are_byte_for_byte_what_numpy_saves() {
        let f = Npy::f64(&[1, 3], &[1.5, -2.0, 3.25]).to_bytes();
        let mut payload = Vec::new();
        for v in [1.5f64, -2.0, 3.25] {
            payload.extend(v.to_le_bytes());
        }
        assert_eq!(f, numpy_save("<f8", "(1, 3)", &payload));
        let i = Npy::i32(&[2], &[7, -1]).to_bytes();
        assert_eq!(
            i,
            numpy_save("<i4", "(2,)", &[7, 0, 0, 0, 0xff, 0xff, 0xff, 0xff])
        );
        assert_eq!(Npy::bool(true).to_bytes(), numpy_save("|b1", "()", &[1]));
        assert_eq!(Npy::str("").to_bytes(), numpy_save("<U1", "()", &[0; 4]));
        let ucs4: Vec<u8> = "LENSMODEL_OPENCV5"
            .bytes()
            .flat_map(|b| [b, 0, 0, 0])
            .collect();
        assert_eq!(
            Npy::str("LENSMODEL_OPENCV5").to_bytes(),
            numpy_save("<U17", "()", &ucs4)
        );
    }

    #[test]
    fn long_headers_stay_aligned_to_64_bytes() {
        let shape: Vec<usize> = vec![1; 40];
        let b = Npy::f64(&shape, &[2.0]).to_bytes();
        let header = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + header) % 64, 0);
        assert_eq!(b[10 + header - 1], b'\n');
        assert_eq!(b.len(), 10 + header + 8);
    }

    /// Reads an archive back by its central directory, as Python's zipfile does.
    fn unzip(z: &[u8]) -> Vec<(String, Vec<u8>)> {
        let u16_at = |i: usize| u16::from_le_bytes([z[i], z[i + 1]]) as usize;
        let u32_at = |i: usize| u32::from_le_bytes(z[i..i + 4].try_into().unwrap()) as usize;
        let end = z.len() - 22;
        assert_eq!(u32_at(end), 0x0605_4b50);
        let (count, mut at) = (u16_at(end + 10), u32_at(end + 16));
        let mut files = Vec::new();
        for _ in 0..count {
            assert_eq!(u32_at(at), 0x0201_4b50);
            let (crc, packed, size) = (u32_at(at + 16), u32_at(at + 20), u32_at(at + 24));
            let name_len = u16_at(at + 28);
            let name = String::from_utf8(z[at + 46..at + 46 + name_len].to_vec()).unwrap();
            let local = u32_at(at + 42);
            assert_eq!(u32_at(local), 0x0403_4b50);
            let start = local + 30 + u16_at(local + 26) + u16_at(local + 28);
            let mut raw = Vec::new();
            DeflateDecoder::new(&z[start..start + packed])
                .read_to_end(&mut raw)
                .unwrap();
            assert_eq!((raw.len(), crc32fast::hash(&raw) as usize), (size, crc));
            files.push((name, raw));
            at += 46 + name_len;
        }
        files
    }

    #[test]
    fn an_archive_holds_every_array_under_its_key() {
        let a = Npy::f64(&[4, 2], &[0.25; 8]);
        let b = Npy::str("x");
        let z = npz(&[("first", a.clone()), ("second", b.clone())]).unwrap();
        let files = unzip(&z);
        assert_eq!(
            files,
            vec![
                ("first.npy".to_string(), a.to_bytes()),
                ("second.npy".to_string(), b.to_bytes())
            ]
        );
    }

    #[test]
    fn base85_is_pythons_b85encode() {
        // base64.b85encode(...) in CPython 3.11.
        for (data, python) in [
            (&b""[..], ""),
            (b"h", "Xa"),
            (b"he", "Xk`"),
            (b"hel", "Xk}~"),
            (b"hell", "Xk~0{"),
            (b"hello", "Xk~0{Zv"),
            (b"\xfa\xfb\xfc\xfd\xfe\xff", "`uqI-{{H"),
            (b"\0\0\0\0", "00000"),
        ] {
            assert_eq!(b85encode(data), python, "{data:?}");
        }
    }

    #[test]
    fn base85_never_needs_escaping_in_a_python_bytes_literal() {
        let all: Vec<u8> = (0..=255).collect();
        let s = b85encode(&all);
        assert!(!s.contains(['\'', '"', '\\']));
        assert_eq!(s.len(), 320);
    }
}
