//! The rmw_zenoh attachment of a sample (rmw_zenoh.md §4): v2 is `i64 seq | i64 source_ts_ns |
//! 0x10 | gid[16]` (33 bytes), v1 labels each value with a LEB128-prefixed string (77 bytes).
//! Only well-formed attachments are read here; anything else goes to the Python path, which
//! makes the dead letter with the exact reason (`fleetlink.roswire.attachment`).

pub struct Attachment {
    pub seq: i64,
    pub source_ts_ns: i64,
    pub gid: [u8; 16],
}

const LABEL_SEQ: &[u8] = b"\x0fsequence_number";
const LABEL_TS: &[u8] = b"\x10source_timestamp";
const LABEL_GID: &[u8] = b"\x0asource_gid";

fn i64_at(b: &[u8], at: usize) -> i64 {
    i64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

pub fn parse(raw: &[u8]) -> Option<Attachment> {
    if raw.len() == 33 {
        if raw[16] != 16 {
            return None;
        }
        return Some(Attachment { seq: i64_at(raw, 0), source_ts_ns: i64_at(raw, 8), gid: raw[17..33].try_into().unwrap() });
    }
    if raw.len() == 77 && raw.starts_with(LABEL_SEQ) {
        let ts_at = LABEL_SEQ.len() + 8;
        let gid_at = ts_at + LABEL_TS.len() + 8;
        if &raw[ts_at..ts_at + LABEL_TS.len()] != LABEL_TS || &raw[gid_at..gid_at + LABEL_GID.len()] != LABEL_GID {
            return None;
        }
        let len_at = gid_at + LABEL_GID.len();
        if raw[len_at] != 16 {
            return None;
        }
        return Some(Attachment {
            seq: i64_at(raw, LABEL_SEQ.len()),
            source_ts_ns: i64_at(raw, ts_at + LABEL_TS.len()),
            gid: raw[len_at + 1..len_at + 17].try_into().unwrap(),
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn v2_and_v1() {
        let mut v2 = vec![];
        v2.extend_from_slice(&7i64.to_le_bytes());
        v2.extend_from_slice(&99i64.to_le_bytes());
        v2.push(16);
        v2.extend_from_slice(&[5u8; 16]);
        let a = parse(&v2).unwrap();
        assert_eq!((a.seq, a.source_ts_ns, a.gid), (7, 99, [5u8; 16]));
        let mut v1 = LABEL_SEQ.to_vec();
        v1.extend_from_slice(&7i64.to_le_bytes());
        v1.extend_from_slice(LABEL_TS);
        v1.extend_from_slice(&99i64.to_le_bytes());
        v1.extend_from_slice(LABEL_GID);
        v1.push(16);
        v1.extend_from_slice(&[5u8; 16]);
        assert_eq!(v1.len(), 77);
        let a = parse(&v1).unwrap();
        assert_eq!((a.seq, a.source_ts_ns, a.gid), (7, 99, [5u8; 16]));
        v2[16] = 15;
        assert!(parse(&v2).is_none());
    }
}
