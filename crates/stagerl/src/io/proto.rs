//! A protocol-buffers encoder for the few messages stagerl writes by hand (TensorBoard events
//! in [`crate::io::tensorboard`], ONNX models in [`crate::export`]): field keys, varints,
//! fixed-width scalars and length-delimited fields, appended to a byte vector.

/// Wire type of a varint field.
const VARINT: u32 = 0;
/// Wire type of an 8-byte field.
const FIXED64: u32 = 1;
/// Wire type of a length-delimited field (bytes, strings, messages, packed arrays).
const LEN: u32 = 2;
/// Wire type of a 4-byte field.
const FIXED32: u32 = 5;

/// Append `v` as a base-128 varint.
pub fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_key(out: &mut Vec<u8>, field: u32, wire: u32) {
    put_varint(out, u64::from(field << 3 | wire));
}

/// Append field `field` as a varint (int32, int64, uint64, enum, bool); negative values take
/// ten bytes, as protobuf encodes them.
pub fn put_int(out: &mut Vec<u8>, field: u32, v: i64) {
    put_key(out, field, VARINT);
    put_varint(out, v as u64);
}

/// Append field `field` as a double.
pub fn put_f64(out: &mut Vec<u8>, field: u32, v: f64) {
    put_key(out, field, FIXED64);
    out.extend_from_slice(&v.to_le_bytes());
}

/// Append field `field` as a float.
pub fn put_f32(out: &mut Vec<u8>, field: u32, v: f32) {
    put_key(out, field, FIXED32);
    out.extend_from_slice(&v.to_le_bytes());
}

/// Append field `field` as length-delimited bytes (a string, a nested message, a packed array).
pub fn put_len_delimited(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, LEN);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// Append field `field` as a string.
pub fn put_str(out: &mut Vec<u8>, field: u32, s: &str) {
    put_len_delimited(out, field, s.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Encodings from the protobuf documentation ("Encoding": 150 as field 1 is `08 96 01`, the
    /// string "testing" as field 2 is `12 07 74 65 73 74 69 6e 67`).
    #[test]
    fn matches_the_documented_encodings() {
        let mut b = Vec::new();
        put_int(&mut b, 1, 150);
        assert_eq!(b, [0x08, 0x96, 0x01]);
        b.clear();
        put_str(&mut b, 2, "testing");
        assert_eq!(b, [0x12, 0x07, 0x74, 0x65, 0x73, 0x74, 0x69, 0x6e, 0x67]);
        b.clear();
        put_int(&mut b, 1, -1);
        assert_eq!(b.len(), 11, "{b:x?}");
        assert_eq!(b[1..], [0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01]);
        b.clear();
        put_f32(&mut b, 3, 1.0);
        assert_eq!(b, [0x1d, 0x00, 0x00, 0x80, 0x3f]);
        b.clear();
        put_f64(&mut b, 1, 1.0);
        assert_eq!(b, [0x09, 0, 0, 0, 0, 0, 0, 0xf0, 0x3f]);
    }
}
