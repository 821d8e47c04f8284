//! Element types of the binary formats and bulk conversion of their arrays to f64.
//!
//! Every reader that finds a binary array hands the raw bytes here, so that decoding is one
//! tight loop per array instead of per-value parsing, and so that every format agrees on
//! what "int" or "Float32" means.

/// Byte order of multi-byte values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Endian {
    Little,
    Big,
}

/// A fixed-size numeric element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

macro_rules! extend_from_chunks {
    ($out:expr, $bytes:expr, $endian:expr, $t:ty) => {{
        const N: usize = std::mem::size_of::<$t>();
        // `chunks_exact` hands out slices of exactly N bytes, so the conversion to an
        // array cannot fail; the fallback only keeps the code free of panics.
        let chunks = $bytes
            .chunks_exact(N)
            .map(|c| <[u8; N]>::try_from(c).unwrap_or([0; N]));
        match $endian {
            Endian::Little => $out.extend(chunks.map(|a| <$t>::from_le_bytes(a) as f64)),
            Endian::Big => $out.extend(chunks.map(|a| <$t>::from_be_bytes(a) as f64)),
        }
    }};
}

impl Scalar {
    /// Size of one element in bytes.
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Appends every whole element of `bytes` to `out` (a trailing partial element is ignored;
    /// callers check lengths first so that they can report truncation with context).
    pub(crate) fn decode_into(self, bytes: &[u8], endian: Endian, out: &mut Vec<f64>) {
        out.reserve(bytes.len() / self.size());
        match self {
            Scalar::I8 => out.extend(bytes.iter().map(|&b| b as i8 as f64)),
            Scalar::U8 => out.extend(bytes.iter().map(|&b| b as f64)),
            Scalar::I16 => extend_from_chunks!(out, bytes, endian, i16),
            Scalar::U16 => extend_from_chunks!(out, bytes, endian, u16),
            Scalar::I32 => extend_from_chunks!(out, bytes, endian, i32),
            Scalar::U32 => extend_from_chunks!(out, bytes, endian, u32),
            Scalar::I64 => extend_from_chunks!(out, bytes, endian, i64),
            Scalar::U64 => extend_from_chunks!(out, bytes, endian, u64),
            Scalar::F32 => extend_from_chunks!(out, bytes, endian, f32),
            Scalar::F64 => extend_from_chunks!(out, bytes, endian, f64),
        }
    }

    /// A value parsed from text, stored as this type would store it: text declared `float`
    /// gives the same f32 numbers as the binary version of the file (and as VTK shows them).
    pub(crate) fn narrow(self, v: f64) -> f64 {
        match self {
            Scalar::F32 => v as f32 as f64,
            _ => v,
        }
    }

    /// Decodes every whole element of `bytes`.
    pub(crate) fn decode(self, bytes: &[u8], endian: Endian) -> Vec<f64> {
        let mut out = Vec::new();
        self.decode_into(bytes, endian, &mut out);
        out
    }

    /// Decodes the single element at the start of `bytes` (0 when `bytes` is too short;
    /// callers check lengths first).
    pub(crate) fn read_one(self, bytes: &[u8], endian: Endian) -> f64 {
        let head = &bytes[..self.size().min(bytes.len())];
        let mut out = Vec::with_capacity(1);
        self.decode_into(head, endian, &mut out);
        out.first().copied().unwrap_or(0.0)
    }

    /// Decodes column `offset..offset+size` of `count` rows that are `stride` bytes apart,
    /// as in records of interleaved properties (PLY vertices, BGEO points).
    pub(crate) fn decode_strided(
        self,
        bytes: &[u8],
        count: usize,
        stride: usize,
        offset: usize,
        endian: Endian,
    ) -> Vec<f64> {
        let size = self.size();
        let mut packed = Vec::with_capacity(count.saturating_mul(size));
        for row in bytes.chunks_exact(stride).take(count) {
            if let Some(field) = row.get(offset..offset + size) {
                packed.extend_from_slice(field);
            }
        }
        self.decode(&packed, endian)
    }
}

/// `count * each` bytes, or `None` when that overflows: a declared count that large can never
/// be backed by the data present, and callers refuse it before allocating anything.
pub(crate) fn byte_len(count: u64, each: u64) -> Option<usize> {
    count
        .checked_mul(each)
        .and_then(|n| usize::try_from(n).ok())
}

/// Parses one whitespace-free text token as a number (integers, decimals, exponents,
/// `nan`/`inf` in any case, as C's strtod would).
pub(crate) fn parse_number(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse::<f64>().ok()
}

/// Iterates over whitespace-separated tokens of a byte buffer, remembering where it stopped
/// so that a reader can switch between text and the rest of a file.
pub(crate) struct Tokens<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
}

impl<'a> Tokens<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Tokens { bytes, pos: 0 }
    }

    /// The next token, or `None` at the end.
    pub(crate) fn next_token(&mut self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        while self.pos < bytes.len() && bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= bytes.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < bytes.len() && !bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some(&bytes[start..self.pos])
    }
}

/// Lossy text of a token or line, for error messages (files may hold any bytes).
pub(crate) fn show(bytes: &[u8]) -> String {
    const MAX: usize = 60;
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(MAX)]);
    // Control bytes (a corrupt file's binary read as a name) are escaped: printed raw they
    // would reach the user's terminal as escape sequences.
    let mut shown = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            shown.extend(c.escape_default());
        } else {
            shown.push(c);
        }
    }
    if bytes.len() > MAX {
        shown.push_str("...");
    }
    shown
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shown_text_is_short_and_escapes_control_bytes() {
        assert_eq!(show(b"pressure"), "pressure");
        assert_eq!(show(b"a\x1b[2Jb\x00"), "a\\u{1b}[2Jb\\u{0}");
        let long = show(&[b'x'; 100]);
        assert!(long.len() == 63 && long.ends_with("..."), "{long}");
    }

    #[test]
    fn decodes_both_byte_orders() {
        let le = 1.5f32.to_le_bytes();
        let be = (-7i32).to_be_bytes();
        assert_eq!(Scalar::F32.decode(&le, Endian::Little), vec![1.5]);
        assert_eq!(Scalar::I32.decode(&be, Endian::Big), vec![-7.0]);
        assert_eq!(Scalar::I8.decode(&[0xff], Endian::Big), vec![-1.0]);
        assert_eq!(Scalar::U16.read_one(&[1, 2, 3], Endian::Big), 258.0);
        assert_eq!(Scalar::U16.read_one(&[1], Endian::Big), 0.0);
    }

    #[test]
    fn strided_columns() {
        // rows of (u8 tag, f32 le value)
        let mut bytes = Vec::new();
        for i in 0..4u8 {
            bytes.push(i);
            bytes.extend_from_slice(&(i as f32 * 0.5).to_le_bytes());
        }
        let v = Scalar::F32.decode_strided(&bytes, 4, 5, 1, Endian::Little);
        assert_eq!(v, vec![0.0, 0.5, 1.0, 1.5]);
        let tags = Scalar::U8.decode_strided(&bytes, 4, 5, 0, Endian::Little);
        assert_eq!(tags, vec![0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn overflowing_sizes_are_none() {
        assert_eq!(byte_len(u64::MAX, 2), None);
        assert_eq!(byte_len(3, 4), Some(12));
    }
}
