//! The one CDR encoder of the crate: ROS 2's serialization (plain CDR, little endian, the
//! `00 01 00 00` encapsulation header; XCDR1 alignment: each primitive on a multiple of its size
//! counted from after the header). Only what the messages of `msgs.rs` need.

/// A CDR message being written.
pub struct Cdr {
    buf: Vec<u8>,
}

/// The encapsulation header: CDR_LE, no options.
const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl Default for Cdr {
    fn default() -> Self {
        Self::new()
    }
}

impl Cdr {
    pub fn new() -> Self {
        let mut buf = Vec::with_capacity(256);
        buf.extend_from_slice(&HEADER);
        Cdr { buf }
    }

    /// The serialized message, header included.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    fn align(&mut self, n: usize) {
        let body = self.buf.len() - HEADER.len();
        let pad = (n - body % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A string: its length with the terminating NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) {
        self.seq_len(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// The length of a sequence that follows. A message here never holds 4 GiB: saturated.
    pub fn seq_len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_alignment_and_strings_follow_cdr() {
        let mut c = Cdr::new();
        c.bool(true);
        c.f64(1.5);
        c.string("ab");
        c.i32(-2);
        let b = c.into_bytes();
        let mut want = vec![0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0];
        want.extend_from_slice(&1.5f64.to_le_bytes());
        want.extend_from_slice(&[3, 0, 0, 0, b'a', b'b', 0, 0]);
        want.extend_from_slice(&(-2i32).to_le_bytes());
        assert_eq!(b, want);
    }
}
