//! Samples the full intake dropped, per publisher, by sequence number.
//!
//! A sample dropped at the intake is counted there; the sequence number it had is then missing
//! from its publisher's samples that `take()` sees. A gap made of such samples is not a loss on
//! the way, so it is excused rather than counted again as `missing`: each sample is counted
//! once. The drops are kept as runs of sequence numbers, so that only the drops a gap spans are
//! excused: drops older than a publisher's first sample taken (the intake was full when it
//! started) or than any sample taken since are forgotten, never held against a later real gap.
//!
//! Bounded: `max_sources` publishers, `MAX_RUNS` runs each (drops beyond are kept as a count,
//! excused against the next gap as far as it goes).

use std::collections::HashMap;

use crate::seq::Seen;

/// Runs kept per publisher: a publisher has one run of drops per stretch the intake was full while
/// it sent (a few between two takes); at most 65,536 publishers x 8 runs x 16 bytes = 8 MiB.
const MAX_RUNS: usize = 8;

/// One publisher's dropped sequence numbers: ascending runs `(first, last)`, and a count of
/// those that did not fit.
#[derive(Default, Debug, PartialEq)]
struct Runs {
    runs: Vec<(i64, i64)>,
    unplaced: u64,
}

impl Runs {
    fn add(&mut self, first: i64, last: i64) {
        if let Some(run) = self.runs.last_mut() {
            if first == run.1.wrapping_add(1) {
                run.1 = last;
                return;
            }
        }
        if self.runs.len() < MAX_RUNS {
            self.runs.push((first, last));
        } else {
            self.unplaced += (last - first) as u64 + 1;
        }
    }

    /// How many of the sequence numbers `first..=last` were dropped; forgets them and every run
    /// before `first`.
    fn within(&mut self, first: i64, last: i64) -> u64 {
        let mut n = 0u64;
        self.runs.retain_mut(|run| {
            if run.1 < first {
                return false;
            }
            if run.0 > last {
                return true;
            }
            n += (run.1.min(last) - run.0.max(first)) as u64 + 1;
            if run.1 > last {
                run.0 = last + 1;
                return true;
            }
            false
        });
        n
    }

    /// Of a gap of `missing` sequence numbers before `seq`, those that were not dropped here.
    fn excuse(&mut self, seq: i64, missing: u64) -> u64 {
        let lost = missing - self.within(seq - missing as i64, seq - 1);
        let unplaced = lost.min(self.unplaced);
        self.unplaced -= unplaced;
        lost - unplaced
    }

    fn is_empty(&self) -> bool {
        self.runs.is_empty() && self.unplaced == 0
    }
}

/// Dropped sequence numbers per publisher GID, for at most `max_sources` publishers (beyond,
/// a drop is counted at the intake and may be counted again as a gap).
pub struct Drops {
    by: HashMap<[u8; 16], Runs>,
    max_sources: usize,
}

impl Drops {
    pub fn new(max_sources: usize) -> Drops {
        Drops { by: HashMap::new(), max_sources }
    }

    pub fn is_empty(&self) -> bool {
        self.by.is_empty()
    }

    fn runs(&mut self, gid: &[u8; 16]) -> Option<&mut Runs> {
        if self.by.len() >= self.max_sources && !self.by.contains_key(gid) {
            return None;
        }
        Some(self.by.entry(*gid).or_default())
    }

    /// A sample of `gid` with sequence number `seq` was dropped.
    pub fn note(&mut self, gid: &[u8; 16], seq: i64) {
        if let Some(runs) = self.runs(gid) {
            runs.add(seq, seq);
        }
    }

    /// Adds the drops noted in `later` (all after those already here, publisher by publisher).
    pub fn absorb(&mut self, later: Drops) {
        for (gid, other) in later.by {
            if let Some(runs) = self.runs(&gid) {
                for (first, last) in other.runs {
                    runs.add(first, last);
                }
                runs.unplaced += other.unplaced;
            }
        }
    }

    /// What the take saw of sample `seq` of `gid` (`seen`, from the sequence tracker), with the
    /// samples this intake dropped taken out of its gap: a gap of drops only is no gap.
    pub fn settle(&mut self, gid: &[u8; 16], seq: i64, seen: Seen) -> Seen {
        if self.by.is_empty() {
            return seen;
        }
        let Some(runs) = self.by.get_mut(gid) else {
            return seen;
        };
        let settled = match seen {
            Seen::Gap(missing) => match runs.excuse(seq, missing) {
                0 => Seen::Next,
                lost => Seen::Gap(lost),
            },
            Seen::LostAtRestart(missing) => Seen::LostAtRestart(runs.excuse(seq, missing)),
            Seen::First | Seen::Next => {
                runs.within(i64::MIN, seq); // drops before a sample taken: no gap will span them
                seen
            }
            Seen::Duplicate => seen,
        };
        if runs.is_empty() {
            self.by.remove(gid);
        }
        settled
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: [u8; 16] = [9u8; 16];

    fn gap(drops: &mut Drops, seq: i64, missing: u64) -> u64 {
        match drops.settle(&G, seq, Seen::Gap(missing)) {
            Seen::Gap(n) => n,
            Seen::Next => 0,
            _ => panic!("a gap stays a gap or goes"),
        }
    }

    #[test]
    fn a_gap_of_drops_only_is_no_gap() {
        let mut d = Drops::new(8);
        d.note(&G, 3);
        d.note(&G, 4);
        assert_eq!(gap(&mut d, 5, 2), 0);
        assert!(d.is_empty());
    }

    #[test]
    fn only_the_drops_a_gap_spans_are_excused() {
        let mut d = Drops::new(8);
        for seq in [3, 4, 9] {
            d.note(&G, seq);
        }
        assert_eq!(gap(&mut d, 6, 3), 1); // 3, 4 dropped here, 5 lost on the way
        assert_eq!(gap(&mut d, 11, 4), 3); // 9 dropped here, 7, 8, 10 lost on the way
        assert!(d.is_empty());
    }

    #[test]
    fn drops_before_a_publishers_first_sample_are_not_held_against_a_later_gap() {
        let mut d = Drops::new(8);
        for seq in 1..=10 {
            d.note(&G, seq); // the intake was full when the publisher started
        }
        d.note(&G, 12);
        assert!(matches!(d.settle(&G, 11, Seen::First), Seen::First));
        assert_eq!(gap(&mut d, 17, 5), 4); // 12 dropped here, 13..16 lost on the way
        assert!(d.is_empty());
    }

    #[test]
    fn runs_beyond_the_bound_are_excused_as_a_count() {
        let mut d = Drops::new(8);
        for n in 0..(MAX_RUNS as i64 + 3) {
            d.note(&G, 2 * n + 1); // every other sample: a run each
        }
        let last = 2 * (MAX_RUNS as i64 + 2) + 1; // 1..=last skipped, MAX_RUNS + 3 of them here
        assert_eq!(gap(&mut d, last + 1, last as u64), last as u64 - (MAX_RUNS as u64 + 3));
        assert!(d.is_empty());
    }

    #[test]
    fn absorbed_drops_continue_the_runs() {
        let mut d = Drops::new(1);
        let mut later = Drops::new(1);
        d.note(&G, 2);
        later.note(&G, 3);
        later.note(&[1u8; 16], 3); // a second publisher: beyond the bound
        d.absorb(later);
        assert_eq!(d.by.len(), 1);
        assert_eq!(d.by[&G].runs, vec![(2, 3)]);
    }
}
