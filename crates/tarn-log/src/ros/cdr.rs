//! A small reader and writer for OMG CDR (XCDR1, "plain CDR"), the encoding ROS 2 uses on
//! the wire and in MCAP logs.
//!
//! A payload starts with a 4-byte encapsulation header: `00 00` big endian or `00 01`
//! little endian, then two option bytes. Primitives are aligned to their own size
//! (8 for `f64`/`u64`) *relative to the first byte after that header*. Strings are a
//! `u32` length that counts the terminating NUL, the bytes, then the NUL; sequences are
//! a `u32` element count followed by the elements; fixed arrays have no count.
//!
//! The same reader decodes ROS 1 serialization ([`Wire::Ros1`], as stored in `.bag` files):
//! no encapsulation header, little endian, no alignment padding, strings without a NUL.
//! The message layouts of the types tarn reads are the same on both wires except
//! `std_msgs/Header`, which carries a `seq` in ROS 1.

/// Why a CDR payload could not be decoded, and at which byte of the payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CdrError {
    /// Byte offset in the payload (including the 4-byte encapsulation header).
    pub offset: usize,
    /// What was wrong.
    pub message: String,
}

impl std::fmt::Display for CdrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "CDR byte {}: {}", self.offset, self.message)
    }
}

impl std::error::Error for CdrError {}

/// Result of CDR decoding.
pub type CdrResult<T> = std::result::Result<T, CdrError>;

/// Byte order of a CDR payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endian {
    /// Little endian (encapsulation `00 01`).
    Little,
    /// Big endian (encapsulation `00 00`).
    Big,
}

/// How a message is serialized.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wire {
    /// ROS 2: CDR with its encapsulation header and alignment.
    Cdr,
    /// ROS 1: little endian, packed, strings without a NUL.
    Ros1,
}

const HEADER: usize = 4;

/// Reads primitives from a CDR payload, keeping alignment (or from a ROS 1 message:
/// [`CdrReader::ros1`]).
pub struct CdrReader<'a> {
    buf: &'a [u8],
    pos: usize,
    endian: Endian,
    wire: Wire,
}

macro_rules! read_prim {
    ($name:ident, $t:ty, $n:expr) => {
        #[doc = concat!("One `", stringify!($t), "`, aligned to its size on the CDR wire. Fails at the end of the payload.")]
        pub fn $name(&mut self) -> CdrResult<$t> {
            self.align($n)?;
            let b = self.take($n, stringify!($t))?;
            let a: [u8; $n] = b.try_into().expect("take returns exactly n bytes");
            Ok(match self.endian {
                Endian::Little => <$t>::from_le_bytes(a),
                Endian::Big => <$t>::from_be_bytes(a),
            })
        }
    };
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header and positions the reader after it.
    pub fn new(buf: &'a [u8]) -> CdrResult<Self> {
        if buf.len() < HEADER {
            return Err(CdrError {
                offset: 0,
                message: format!(
                    "payload of {} bytes is shorter than the 4-byte encapsulation header",
                    buf.len()
                ),
            });
        }
        let endian = match (buf[0], buf[1]) {
            (0, 0) => Endian::Big,
            (0, 1) => Endian::Little,
            (a, b) => {
                return Err(CdrError {
                    offset: 0,
                    message: format!(
                        "encapsulation kind {a:#04x}{b:02x} is not plain CDR (0x0000 big endian or 0x0001 little endian)"
                    ),
                })
            }
        };
        Ok(CdrReader {
            buf,
            pos: HEADER,
            endian,
            wire: Wire::Cdr,
        })
    }

    /// A reader of a ROS 1 serialized message (no header, little endian, packed).
    pub fn ros1(buf: &'a [u8]) -> Self {
        CdrReader {
            buf,
            pos: 0,
            endian: Endian::Little,
            wire: Wire::Ros1,
        }
    }

    /// A reader of `buf` serialized as `wire`.
    pub fn for_wire(buf: &'a [u8], wire: Wire) -> CdrResult<Self> {
        match wire {
            Wire::Cdr => Self::new(buf),
            Wire::Ros1 => Ok(Self::ros1(buf)),
        }
    }

    /// How the payload is serialized.
    pub fn wire(&self) -> Wire {
        self.wire
    }

    /// Byte order of the payload (always little on the ROS 1 wire).
    pub fn endian(&self) -> Endian {
        self.endian
    }

    /// Current byte offset in the payload.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    /// An error at the current position, with `message`.
    pub fn err(&self, message: impl Into<String>) -> CdrError {
        CdrError {
            offset: self.pos,
            message: message.into(),
        }
    }

    fn align(&mut self, n: usize) -> CdrResult<()> {
        if self.wire == Wire::Ros1 {
            return Ok(());
        }
        let rel = self.pos - HEADER;
        let pad = (n - rel % n) % n;
        if pad > self.remaining() {
            // Padding at the very end is allowed to be missing only if nothing follows;
            // a read after it will fail with a clear message anyway.
            return Err(self.err(format!("payload ends inside {pad} bytes of alignment")));
        }
        self.pos += pad;
        Ok(())
    }

    fn take(&mut self, n: usize, what: &str) -> CdrResult<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(format!(
                "payload ends: {what} needs {n} bytes, {} remain",
                self.remaining()
            )));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    /// One byte. Fails at the end of the payload.
    pub fn u8(&mut self) -> CdrResult<u8> {
        Ok(self.take(1, "u8")?[0])
    }

    /// A `bool` byte: any non-zero value is true. Fails at the end of the payload.
    pub fn bool(&mut self) -> CdrResult<bool> {
        Ok(self.u8()? != 0)
    }

    read_prim!(u16, u16, 2);
    read_prim!(i16, i16, 2);
    read_prim!(u32, u32, 4);
    read_prim!(i32, i32, 4);
    read_prim!(u64, u64, 8);
    read_prim!(i64, i64, 8);
    read_prim!(f32, f32, 4);
    read_prim!(f64, f64, 8);

    /// A string: u32 length (counting the NUL), bytes, NUL (ROS 1: u32 length, bytes).
    /// Invalid UTF-8 is an error.
    pub fn string(&mut self) -> CdrResult<String> {
        let start = self.pos;
        let n = self.u32()? as usize;
        if self.wire == Wire::Ros1 {
            let b = self.take(n, "string")?;
            return String::from_utf8(b.to_vec()).map_err(|_| CdrError {
                offset: start,
                message: "string is not UTF-8".into(),
            });
        }
        if n == 0 {
            // Some writers emit 0 for an empty string; accept it.
            return Ok(String::new());
        }
        let b = self.take(n, "string")?;
        let body = match b.split_last() {
            Some((0, body)) => body,
            _ => {
                return Err(CdrError {
                    offset: start,
                    message: "string is not NUL-terminated".into(),
                })
            }
        };
        String::from_utf8(body.to_vec()).map_err(|_| CdrError {
            offset: start,
            message: "string is not UTF-8".into(),
        })
    }

    /// A sequence length; checks that at least `len * min_elem_size` bytes remain so a
    /// corrupt length cannot make the caller allocate gigabytes.
    pub fn seq_len(&mut self, min_elem_size: usize, what: &str) -> CdrResult<usize> {
        let n = self.u32()? as usize;
        if n.saturating_mul(min_elem_size) > self.remaining() {
            return Err(self.err(format!(
                "{what} declares {n} elements but only {} bytes remain",
                self.remaining()
            )));
        }
        Ok(n)
    }

    /// A `uint8[]` sequence, borrowed.
    pub fn bytes(&mut self, what: &str) -> CdrResult<&'a [u8]> {
        let n = self.seq_len(1, what)?;
        self.take(n, what)
    }

    /// A `float64[]` sequence.
    pub fn f64_seq(&mut self, what: &str) -> CdrResult<Vec<f64>> {
        let n = self.seq_len(8, what)?;
        (0..n).map(|_| self.f64()).collect()
    }

    /// A `float64[N]` fixed array.
    pub fn f64_array<const N: usize>(&mut self) -> CdrResult<[f64; N]> {
        let mut a = [0.0; N];
        for v in a.iter_mut() {
            *v = self.f64()?;
        }
        Ok(a)
    }
}

/// Writes a CDR payload (header included).
pub struct CdrWriter {
    buf: Vec<u8>,
    endian: Endian,
}

macro_rules! write_prim {
    ($name:ident, $t:ty, $n:expr) => {
        #[doc = concat!("One `", stringify!($t), "`, aligned to its size.")]
        pub fn $name(&mut self, v: $t) {
            self.align($n);
            match self.endian {
                Endian::Little => self.buf.extend_from_slice(&v.to_le_bytes()),
                Endian::Big => self.buf.extend_from_slice(&v.to_be_bytes()),
            }
        }
    };
}

impl CdrWriter {
    /// A writer of byte order `endian`, with the encapsulation header written.
    pub fn new(endian: Endian) -> Self {
        Self::with_capacity(endian, 64)
    }

    /// Like [`CdrWriter::new`], with room for `cap` payload bytes.
    pub fn with_capacity(endian: Endian, cap: usize) -> Self {
        let mut buf = Vec::with_capacity(cap + HEADER);
        buf.extend_from_slice(match endian {
            Endian::Big => &[0, 0, 0, 0],
            Endian::Little => &[0, 1, 0, 0],
        });
        CdrWriter { buf, endian }
    }

    fn align(&mut self, n: usize) {
        let rel = self.buf.len() - HEADER;
        let pad = (n - rel % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// One byte.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// A `bool` as one byte, 0 or 1.
    pub fn bool(&mut self, v: bool) {
        self.buf.push(v as u8);
    }

    write_prim!(u16, u16, 2);
    write_prim!(i16, i16, 2);
    write_prim!(u32, u32, 4);
    write_prim!(i32, i32, 4);
    write_prim!(u64, u64, 8);
    write_prim!(i64, i64, 8);
    write_prim!(f32, f32, 4);
    write_prim!(f64, f64, 8);

    /// A string: u32 length counting the NUL, the bytes, a NUL.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A `uint8[]` sequence: u32 count, then the bytes.
    pub fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
    }

    /// A `float64[]` sequence: u32 count, then the aligned values.
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.u32(v.len() as u32);
        for &x in v {
            self.f64(x);
        }
    }

    /// A `float64[N]` fixed array: the aligned values, no count.
    pub fn f64_array(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }

    /// The payload, encapsulation header included.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn alignment_is_relative_to_payload_start() {
        // u8 then f64: the f64 starts at payload offset 8 (header 4 + u8 1 + pad 7... relative
        // offset 1 → pad to 8), i.e. absolute byte 12.
        let mut w = CdrWriter::new(Endian::Little);
        w.u8(7);
        w.f64(1.5);
        let b = w.finish();
        assert_eq!(b.len(), 4 + 8 + 8);
        assert_eq!(&b[12..20], &1.5f64.to_le_bytes());
    }

    #[test]
    fn known_bytes_big_endian() {
        // "ab" as a CDR string, then u16 0x0102, big endian.
        let bytes = [0, 0, 0, 0, 0, 0, 0, 3, b'a', b'b', 0, 0, 0x01, 0x02];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.endian(), Endian::Big);
        assert_eq!(r.string().unwrap(), "ab");
        assert_eq!(r.u16().unwrap(), 0x0102);
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn truncated_payload_names_offset() {
        let bytes = [0, 1, 0, 0, 1, 2];
        let mut r = CdrReader::new(&bytes).unwrap();
        let e = r.u32().unwrap_err();
        assert_eq!(e.offset, 4);
        assert!(e.message.contains("needs 4 bytes"), "{e}");
    }

    #[test]
    fn huge_sequence_length_is_rejected() {
        let bytes = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert!(r.bytes("data").is_err());
    }

    #[test]
    fn bad_encapsulation_is_rejected() {
        assert!(CdrReader::new(&[0, 3, 0, 0]).is_err());
        assert!(CdrReader::new(&[0, 1]).is_err());
    }

    proptest! {
        #[test]
        fn round_trip_both_endians(
            big in any::<bool>(), a in any::<u8>(), b in any::<i32>(), c in any::<f64>(),
            s in "[a-z/_]{0,12}", d in any::<u16>(), e in proptest::collection::vec(any::<u8>(), 0..20),
            f in any::<u64>(), g in any::<f32>(),
        ) {
            let endian = if big { Endian::Big } else { Endian::Little };
            let mut w = CdrWriter::new(endian);
            w.u8(a); w.i32(b); w.f64(c); w.string(&s); w.u16(d); w.bytes(&e); w.u64(f); w.f32(g);
            let buf = w.finish();
            let mut r = CdrReader::new(&buf).unwrap();
            prop_assert_eq!(r.endian(), endian);
            prop_assert_eq!(r.u8().unwrap(), a);
            prop_assert_eq!(r.i32().unwrap(), b);
            prop_assert_eq!(r.f64().unwrap().to_bits(), c.to_bits());
            prop_assert_eq!(r.string().unwrap(), s);
            prop_assert_eq!(r.u16().unwrap(), d);
            prop_assert_eq!(r.bytes("e").unwrap(), &e[..]);
            prop_assert_eq!(r.u64().unwrap(), f);
            prop_assert_eq!(r.f32().unwrap().to_bits(), g.to_bits());
            prop_assert_eq!(r.remaining(), 0);
        }
    }
}
