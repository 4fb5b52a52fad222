//! Per-publisher sequence numbers: gaps (samples lost before the edge saw them) and duplicates,
//! as `fleetlink.roswire.sequence.SequenceTracker` counts them. Bounded: the least recently seen
//! publisher is forgotten beyond `max_sources`.

use std::collections::HashMap;

pub enum Seen {
    First,
    Next,
    Gap(u64),
    /// The first sample from a publisher restored with `seed` skips this many: samples it sent
    /// while the edge was down, or that the edge had not spooled when it stopped.
    LostAtRestart(u64),
    Duplicate,
}

pub struct SeqTracker {
    last: HashMap<[u8; 16], (i64, u64)>,
    restored: std::collections::HashSet<[u8; 16]>,
    tick: u64,
    max_sources: usize,
}

impl SeqTracker {
    pub fn new(max_sources: usize) -> SeqTracker {
        SeqTracker { last: HashMap::new(), restored: Default::default(), tick: 0, max_sources: max_sources.max(1) }
    }

    /// What a previous run spooled last from `gid`: its next sample tells what was lost between.
    pub fn seed(&mut self, gid: &[u8; 16], seq: i64) {
        if self.last.len() < self.max_sources || self.last.contains_key(gid) {
            self.tick += 1;
            self.last.insert(*gid, (seq, self.tick));
            self.restored.insert(*gid);
        }
    }

    pub fn observe(&mut self, gid: &[u8; 16], seq: i64) -> Seen {
        self.tick += 1;
        let tick = self.tick;
        match self.last.get_mut(gid) {
            None => {
                if self.last.len() >= self.max_sources {
                    if let Some(oldest) = self.last.iter().min_by_key(|(_, v)| v.1).map(|(k, _)| *k) {
                        self.last.remove(&oldest);
                        self.restored.remove(&oldest);
                    }
                }
                self.last.insert(*gid, (seq, tick));
                Seen::First
            }
            Some(entry) => {
                entry.1 = tick;
                let last = entry.0;
                let restored = !self.restored.is_empty() && self.restored.remove(gid);
                if seq == last.wrapping_add(1) {
                    entry.0 = seq;
                    Seen::Next
                } else if seq > last {
                    entry.0 = seq;
                    let missing = (seq - last - 1) as u64;
                    if restored {
                        Seen::LostAtRestart(missing)
                    } else {
                        Seen::Gap(missing)
                    }
                } else {
                    Seen::Duplicate
                }
            }
        }
    }

    /// The last sequence number seen from `gid`.
    pub fn last(&self, gid: &[u8; 16]) -> Option<i64> {
        self.last.get(gid).map(|v| v.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restored_publisher_reports_what_it_lost_once() {
        let mut t = SeqTracker::new(8);
        let g = [7u8; 16];
        t.seed(&g, 10);
        assert!(matches!(t.observe(&g, 14), Seen::LostAtRestart(3)));
        assert!(matches!(t.observe(&g, 16), Seen::Gap(1)));
    }

    #[test]
    fn gaps_and_duplicates() {
        let mut t = SeqTracker::new(2);
        let g = [1u8; 16];
        assert!(matches!(t.observe(&g, 1), Seen::First));
        assert!(matches!(t.observe(&g, 2), Seen::Next));
        assert!(matches!(t.observe(&g, 5), Seen::Gap(2)));
        assert!(matches!(t.observe(&g, 5), Seen::Duplicate));
        t.observe(&[2u8; 16], 1);
        t.observe(&[3u8; 16], 1); // evicts gid 1, the least recently seen
        assert!(t.last(&g).is_none());
    }
}
