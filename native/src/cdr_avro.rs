//! CDR (XCDR1, little-endian) -> Avro binary, driven by a type layout compiled in Python
//! (`fleetlink.edge.runtime.native_plan.layout_program`). The same rules as the generated Python
//! converter (`fleetlink.schemas.gen_cdr_avro`): alignment relative to byte 4, floats copied,
//! integers as zigzag varints, strings and byte sequences length-prefixed, arrays as one Avro
//! block plus its terminating 0. Anything the fast path does not take (big-endian payloads,
//! malformed input, out-of-range values) is an `Err`: the caller hands the sample to the Python
//! path, which makes the same record or the dead letter with its reason.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Bool,
    Byte,
    Char,
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

impl Kind {
    fn from_code(code: u8) -> Option<Kind> {
        Some(match code {
            0 => Kind::Bool,
            1 => Kind::Byte,
            2 => Kind::Char,
            3 => Kind::I8,
            4 => Kind::U8,
            5 => Kind::I16,
            6 => Kind::U16,
            7 => Kind::I32,
            8 => Kind::U32,
            9 => Kind::I64,
            10 => Kind::U64,
            11 => Kind::F32,
            12 => Kind::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Kind::Bool | Kind::Byte | Kind::Char | Kind::I8 | Kind::U8 => 1,
            Kind::I16 | Kind::U16 => 2,
            Kind::I32 | Kind::U32 | Kind::F32 => 4,
            Kind::I64 | Kind::U64 | Kind::F64 => 8,
        }
    }

    fn is_bytes(self) -> bool {
        matches!(self, Kind::Byte | Kind::Char | Kind::U8)
    }

    fn is_float(self) -> bool {
        matches!(self, Kind::F32 | Kind::F64)
    }
}

#[derive(Debug)]
pub enum Node {
    Prim(Kind),
    Text(u32),
    Record(Vec<Node>),
    Array { elem: Box<Node>, size: u32, fixed: bool, min_size: u32 },
}

/// A compiled layout. Program bytes (all integers little-endian):
/// `1 kind:u8` primitive, `2 bound:u32` string, `3 n:u16 node*n` record,
/// `4 fixed:u8 size:u32 min_size:u32 node` array or sequence.
pub struct Program {
    root: Node,
}

#[derive(Debug)]
pub struct Malformed;

type Res<T> = Result<T, Malformed>;

impl Program {
    pub fn parse(code: &[u8]) -> Result<Program, String> {
        let mut pos = 0usize;
        let root = parse_node(code, &mut pos, 0).map_err(|e| format!("invalid layout program: {e}"))?;
        if pos != code.len() {
            return Err(format!("invalid layout program: {} trailing bytes", code.len() - pos));
        }
        Ok(Program { root })
    }

    /// The Avro body of one CDR message, appended to `out` (on `Err`, `out` is left as it was).
    pub fn convert(&self, buf: &[u8], out: &mut Vec<u8>) -> Res<()> {
        let mark = out.len();
        let result = self.convert_inner(buf, out);
        if result.is_err() {
            out.truncate(mark);
        }
        result
    }

    fn convert_inner(&self, buf: &[u8], out: &mut Vec<u8>) -> Res<()> {
        if buf.len() < 4 || buf[0] != 0 || buf[1] != 1 {
            return Err(Malformed); // big-endian or another encapsulation: the Python path
        }
        let mut cur = Cursor { buf, pos: 4 };
        node(&self.root, &mut cur, out)?;
        if buf.len() - cur.pos > 3 {
            return Err(Malformed);
        }
        Ok(())
    }
}

fn parse_node(code: &[u8], pos: &mut usize, depth: usize) -> Result<Node, String> {
    if depth > 64 {
        return Err("layout program nests too deeply".into());
    }
    let tag = take(code, pos, 1)?[0];
    match tag {
        1 => {
            let k = take(code, pos, 1)?[0];
            Kind::from_code(k).map(Node::Prim).ok_or_else(|| format!("unknown primitive code {k}"))
        }
        2 => Ok(Node::Text(u32_at(code, pos)?)),
        3 => {
            let n = u16::from_le_bytes(take(code, pos, 2)?.try_into().unwrap()) as usize;
            let mut fields = Vec::with_capacity(n);
            for _ in 0..n {
                fields.push(parse_node(code, pos, depth + 1)?);
            }
            Ok(Node::Record(fields))
        }
        4 => {
            let fixed = take(code, pos, 1)?[0] != 0;
            let size = u32_at(code, pos)?;
            let min_size = u32_at(code, pos)?;
            let elem = parse_node(code, pos, depth + 1)?;
            if matches!(elem, Node::Array { .. }) {
                return Err("an array of arrays is not a ROS type".into());
            }
            Ok(Node::Array { elem: Box::new(elem), size, fixed, min_size })
        }
        other => Err(format!("unknown layout tag {other}")),
    }
}

fn take<'a>(code: &'a [u8], pos: &mut usize, n: usize) -> Result<&'a [u8], String> {
    let end = *pos + n;
    if end > code.len() {
        return Err("truncated layout program".into());
    }
    let s = &code[*pos..end];
    *pos = end;
    Ok(s)
}

fn u32_at(code: &[u8], pos: &mut usize) -> Result<u32, String> {
    Ok(u32::from_le_bytes(take(code, pos, 4)?.try_into().unwrap()))
}

struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    #[inline]
    fn align(&mut self, a: usize) {
        let rel = self.pos - 4;
        self.pos = 4 + ((rel + a - 1) & !(a - 1));
    }

    #[inline]
    fn bytes(&mut self, n: usize) -> Res<&'a [u8]> {
        let end = self.pos.checked_add(n).ok_or(Malformed)?;
        if end > self.buf.len() {
            return Err(Malformed);
        }
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    #[inline]
    fn u32(&mut self) -> Res<u32> {
        self.align(4);
        Ok(u32::from_le_bytes(self.bytes(4)?.try_into().unwrap()))
    }
}

#[inline]
fn varint(out: &mut Vec<u8>, mut u: u64) {
    while u >= 0x80 {
        out.push((u as u8 & 0x7F) | 0x80);
        u >>= 7;
    }
    out.push(u as u8);
}

#[inline]
fn zz(out: &mut Vec<u8>, v: i64) {
    varint(out, ((v << 1) ^ (v >> 63)) as u64);
}

/// The block header of an Avro array of `n` items (nothing for an empty array).
#[inline]
fn count(out: &mut Vec<u8>, n: u64) {
    if n > 0 {
        varint(out, n << 1);
    }
}

#[inline]
fn int_value(kind: Kind, b: &[u8]) -> Res<i64> {
    Ok(match kind {
        Kind::Byte | Kind::Char | Kind::U8 => b[0] as i64,
        Kind::I8 => b[0] as i8 as i64,
        Kind::I16 => i16::from_le_bytes([b[0], b[1]]) as i64,
        Kind::U16 => u16::from_le_bytes([b[0], b[1]]) as i64,
        Kind::I32 => i32::from_le_bytes(b.try_into().unwrap()) as i64,
        Kind::U32 => u32::from_le_bytes(b.try_into().unwrap()) as i64,
        Kind::I64 => i64::from_le_bytes(b.try_into().unwrap()),
        Kind::U64 => {
            let v = u64::from_le_bytes(b.try_into().unwrap());
            if v > i64::MAX as u64 {
                return Err(Malformed); // does not fit an Avro long: the Python path says so
            }
            v as i64
        }
        Kind::Bool | Kind::F32 | Kind::F64 => unreachable!("not an integer kind"),
    })
}

fn prim(kind: Kind, cur: &mut Cursor, out: &mut Vec<u8>) -> Res<()> {
    let size = kind.size();
    cur.align(size);
    let b = cur.bytes(size)?;
    match kind {
        Kind::F32 | Kind::F64 => out.extend_from_slice(b),
        Kind::Bool => {
            if b[0] > 1 {
                return Err(Malformed);
            }
            out.push(b[0]);
        }
        _ => zz(out, int_value(kind, b)?),
    }
    Ok(())
}

fn text(bound: u32, cur: &mut Cursor, out: &mut Vec<u8>) -> Res<()> {
    let len = cur.u32()? as usize;
    if len == 0 || (bound > 0 && len > bound as usize + 1) {
        return Err(Malformed);
    }
    let b = cur.bytes(len)?;
    if b[len - 1] != 0 {
        return Err(Malformed);
    }
    let s = &b[..len - 1];
    if !s.is_ascii() && std::str::from_utf8(s).is_err() {
        return Err(Malformed);
    }
    zz(out, s.len() as i64);
    out.extend_from_slice(s);
    Ok(())
}

/// `n` primitives starting at the cursor (already aligned), as Avro bytes or an Avro array.
fn prim_items(kind: Kind, n: usize, cur: &mut Cursor, out: &mut Vec<u8>) -> Res<()> {
    let size = kind.size();
    let data = cur.bytes(n.checked_mul(size).ok_or(Malformed)?)?;
    if kind.is_bytes() {
        zz(out, n as i64);
        out.extend_from_slice(data);
        return Ok(());
    }
    count(out, n as u64);
    if kind.is_float() {
        out.extend_from_slice(data);
    } else if kind == Kind::Bool {
        if data.iter().any(|&b| b > 1) {
            return Err(Malformed);
        }
        out.extend_from_slice(data);
    } else {
        for item in data.chunks_exact(size) {
            zz(out, int_value(kind, item)?);
        }
    }
    out.push(0);
    Ok(())
}

fn node(n: &Node, cur: &mut Cursor, out: &mut Vec<u8>) -> Res<()> {
    match n {
        Node::Prim(kind) => prim(*kind, cur, out),
        Node::Text(bound) => text(*bound, cur, out),
        Node::Record(fields) => {
            for f in fields {
                node(f, cur, out)?;
            }
            Ok(())
        }
        Node::Array { elem, size, fixed, min_size } => {
            let n = if *fixed {
                *size as usize
            } else {
                let n = cur.u32()? as usize;
                if *size > 0 && n > *size as usize {
                    return Err(Malformed);
                }
                n
            };
            if let Node::Prim(kind) = **elem {
                if n > 0 || *fixed {
                    cur.align(kind.size());
                }
                return prim_items(kind, n, cur, out);
            }
            if !*fixed {
                let smallest = (*min_size).max(1) as usize;
                if n.checked_mul(smallest).map_or(true, |need| need > cur.buf.len() - cur.pos) {
                    return Err(Malformed);
                }
            }
            count(out, n as u64);
            for _ in 0..n {
                node(elem, cur, out)?;
            }
            out.push(0);
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zigzag_and_counts() {
        let mut v = vec![];
        zz(&mut v, -1);
        zz(&mut v, 64);
        count(&mut v, 0);
        count(&mut v, 3);
        assert_eq!(v, vec![1, 0x80, 0x01, 6]);
    }

    #[test]
    fn a_string_and_a_double() {
        // record { string s; float64 d }
        let prog = Program::parse(&[3, 2, 0, 2, 0, 0, 0, 0, 1, 12]).unwrap();
        let mut buf = vec![0, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0, 0];
        buf.extend_from_slice(&1.5f64.to_le_bytes());
        let mut out = vec![];
        prog.convert(&buf, &mut out).unwrap();
        let mut want = vec![4, b'h', b'i'];
        want.extend_from_slice(&1.5f64.to_le_bytes());
        assert_eq!(out, want);
        buf[10] = 1; // not NUL-terminated
        assert!(prog.convert(&buf, &mut out).is_err());
    }
}
