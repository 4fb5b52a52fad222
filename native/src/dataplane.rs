//! The edge's receive path: one Zenoh session, any number of subscriptions feeding ONE bounded
//! intake (no thread per subscription), and `take()`, which turns what arrived into spool record
//! payloads without holding the GIL.
//!
//! A subscription callback (on Zenoh's threads) copies the sample into the intake and returns;
//! when the intake is at its bound (samples or bytes) the sample is dropped and counted, so
//! Zenoh's buffers never pile up behind a slow consumer. `take()` reads the attachment, follows
//! each publisher's sequence numbers, and for a data key with a *plan* (installed by the Python
//! side once it has decided how a key maps) converts CDR to Avro and writes each mapping's
//! record payload (`fleetlink.wire.records.PayloadTemplate` format) into one group per delivery
//! class. Everything else — keys without a plan, attachments that do not parse, payloads the
//! converter refuses — goes back to Python as a raw sample, where the general path makes the
//! same record or the dead letter.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use zenoh::pubsub::Subscriber;
use zenoh::{Config, Session, Wait};

use crate::attachment;
use crate::cdr_avro::Program;
use crate::drops::Drops;
use crate::seq::{SeqTracker, Seen};
use crate::wakeups;

const FLAG_SOURCE_SEQ: u8 = 0x04;
/// A lane that only counts: a mapping that declares another ROS type than the key carries.
pub const MISMATCH: u32 = u32::MAX;

fn zerr<E: std::fmt::Display>(e: E) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

fn now_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0)
}

struct Raw {
    sub: u32,
    key: String,
    payload: Vec<u8>,
    attachment: Option<Vec<u8>>,
    received_ns: i64,
}

impl Raw {
    fn size(&self) -> usize {
        self.payload.len() + self.attachment.as_ref().map_or(0, |a| a.len()) + self.key.len() + 64
    }
}

#[derive(Default)]
struct SubAtomics {
    received: AtomicU64,
    dropped: AtomicU64,
}

/// Per data key (topic, type, hash): what arrived and what its publishers' sequence numbers say.
#[derive(Default, Clone, Copy)]
struct KeyCounts {
    received: u64,
    gaps: u64,
    missing: u64,
    duplicates: u64,
    lost_at_restart: u64,
    /// Samples that made no record: no mapping takes their key (a robot not registered, or not
    /// yet), so they are counted here rather than lost without a trace.
    unmapped: u64,
}

/// Data keys counted one by one at most; more (a peer inventing keys) are counted together.
const MAX_KEYS: usize = 65536;
/// Plans kept at most; keys beyond take the Python path (counted there).
const MAX_PLANS: usize = 65536;
const OTHER_KEYS: &str = "*";
/// Publishers whose intake drops are remembered between two takes.
const MAX_DROP_SOURCES: usize = 65536;

struct Queue {
    items: VecDeque<Raw>,
    bytes: usize,
    high_water: usize,
    woken: bool,
    /// While a take collects for company: how many samples it takes at most (0: none collects).
    /// The sample that makes that many wakes it, so that a backlog does not wait out the window.
    want: usize,
    /// Per publisher GID, the samples dropped here since the last take (`Drops`).
    dropped_by: Drops,
}

struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
    max_items: usize,
    max_bytes: usize,
    dropped: AtomicU64,
    dropped_bytes: AtomicU64,
    taken: AtomicU64,
    /// How long the receive thread waits after a sample that woke it (zero: never)...
    coalesce: Duration,
    /// ... and while `busy`.
    busy_coalesce: Duration,
    /// Where blocks are not counted: when the last sample arrived (or the last wait ended), in ns
    /// from `started`.
    last_ns: AtomicU64,
    started: Instant,
    /// Waits made: each one a wake-up of the receive thread shared by the samples that followed.
    coalesced: AtomicU64,
    /// Samples arrive at the busy rate (`wait_and_drain`): each wait is `busy_coalesce`.
    busy: AtomicBool,
}

/// Where a thread's blocks are not counted: a sample this long after the one before found the
/// receive thread idle.
const IDLE_GAP_NS: u64 = 50_000;

impl Shared {
    /// Called for each sample on the session's receive thread, before it is offered: whether the
    /// sample woke the thread (it had blocked since the last sample: at steady rates each sample
    /// comes on its own, a wake-up, a socket read and a thread switch a sample) rather than being
    /// read on from the socket's backlog.
    fn woke(&self) -> bool {
        if self.coalesce.is_zero() && self.busy_coalesce.is_zero() {
            return false;
        }
        if let Some(blocked) = wakeups::blocked_since_settled() {
            return blocked;
        }
        let now = self.started.elapsed().as_nanos() as u64;
        let last = self.last_ns.swap(now, Ordering::Relaxed);
        now.saturating_sub(last) > IDLE_GAP_NS
    }

    /// After a sample that `woke` the receive thread, wait `coalesce` (`busy_coalesce` while
    /// `busy`) before reading on, so that the samples arriving meanwhile are read together from the
    /// socket: one wake-up for many. Samples read from a backlog (a burst, those that came
    /// during a wait, a thread preempted while reading) never wait. Adds at most the wait to a
    /// sample's latency.
    fn coalesce(&self, woke: bool) {
        if self.coalesce.is_zero() && self.busy_coalesce.is_zero() {
            return;
        }
        let wait = if self.busy.load(Ordering::Relaxed) { self.busy_coalesce } else { self.coalesce };
        if woke && !wait.is_zero() {
            std::thread::sleep(wait);
            self.coalesced.fetch_add(1, Ordering::Relaxed);
            self.last_ns.store(self.started.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
        wakeups::settle(); // the wait, or the intake's lock, is not the next sample's wake-up
    }

    fn offer(&self, raw: Raw, sub: &SubAtomics) {
        sub.received.fetch_add(1, Ordering::Relaxed);
        let size = raw.size();
        let mut q = self.queue.lock().unwrap();
        if q.items.len() >= self.max_items || q.bytes + size > self.max_bytes {
            // under the lock: the next sample of this publisher cannot be taken before its drop
            // is known there (Drops)
            if let Some(att) = raw.attachment.as_deref().and_then(attachment::parse) {
                q.dropped_by.note(&att.gid, att.seq);
            }
            drop(q);
            sub.dropped.fetch_add(1, Ordering::Relaxed);
            self.dropped.fetch_add(1, Ordering::Relaxed);
            self.dropped_bytes.fetch_add(size as u64, Ordering::Relaxed);
            return;
        }
        let was_empty = q.items.is_empty();
        let wanted = q.want != 0 && q.items.len() + 1 == q.want;
        q.items.push_back(raw);
        q.bytes += size;
        if q.items.len() > q.high_water {
            q.high_water = q.items.len();
        }
        drop(q);
        if was_empty || wanted {
            self.ready.notify_one();
        }
    }
}

struct Lane {
    id: u32,
    program: Option<Arc<Program>>,
    head: Vec<u8>,
    tail: Vec<u8>,
    flags: u8,
    delivery: u8,
}

/// The rate samples are taken at, over windows of some 100 ms (`wait_and_drain`).
struct Pace {
    since: Instant,
    count: usize,
    rate: f64,
}

impl Pace {
    fn note(&mut self, taken: usize) {
        self.count += taken;
        let elapsed = self.since.elapsed().as_secs_f64();
        if elapsed >= 0.1 {
            self.rate = self.count as f64 / elapsed;
            self.count = 0;
            self.since = Instant::now();
        }
    }
}

struct Plan {
    lanes: Vec<Lane>,
}

struct State {
    programs: HashMap<u32, Arc<Program>>,
    plans: HashMap<String, Arc<Plan>>,
    seqs: SeqTracker,
    intake_drops: Drops,
    keys: HashMap<String, KeyCounts>,
    subs: HashMap<u32, Arc<SubAtomics>>,
    topics: HashMap<u32, String>,
}

/// Records of one delivery class being gathered into groups (`fleetlink.wire.groups`):
/// `count u32 | n_fingerprints u16 | fingerprint[8]* | {length u32 | payload}*`.
struct Grouper {
    max_records: u32,
    max_bytes: usize,
    count: u32,
    fingerprints: Vec<[u8; 8]>,
    body: Vec<u8>,
    done: Vec<Vec<u8>>,
}

impl Grouper {
    fn new(max_records: u32, max_bytes: usize) -> Grouper {
        Grouper { max_records: max_records.max(1), max_bytes: max_bytes.max(1), count: 0, fingerprints: vec![], body: vec![], done: vec![] }
    }

    /// Room for a record of `payload_len` bytes, closing the current group if it is full.
    fn reserve(&mut self, payload_len: usize) {
        if self.count > 0 && (self.count >= self.max_records || self.body.len() + payload_len + 4 > self.max_bytes) {
            self.close();
        }
        self.body.reserve(4 + payload_len);
    }

    fn note(&mut self, fingerprint: &[u8]) {
        let fp: [u8; 8] = fingerprint.try_into().unwrap_or([0; 8]);
        if !self.fingerprints.contains(&fp) {
            self.fingerprints.push(fp);
        }
        self.count += 1;
    }

    fn close(&mut self) {
        if self.count == 0 {
            return;
        }
        let mut group = Vec::with_capacity(6 + 8 * self.fingerprints.len() + self.body.len());
        group.extend_from_slice(&self.count.to_le_bytes());
        group.extend_from_slice(&(self.fingerprints.len() as u16).to_le_bytes());
        self.fingerprints.sort_unstable();
        for fp in &self.fingerprints {
            group.extend_from_slice(fp);
        }
        group.extend_from_slice(&self.body);
        self.done.push(group);
        self.count = 0;
        self.fingerprints.clear();
        self.body.clear();
    }
}

impl Taken {
    /// `seq` of publisher `gid` made records (or went to the Python path): its mark, unless an
    /// earlier one of this take is higher.
    fn mark(&mut self, gid: [u8; 16], seq: i64) {
        let known = self.marks.entry(gid).or_insert(seq);
        if seq > *known {
            *known = seq;
        }
    }

    /// The marks as a marks block (`fleetlink.edge.spool.marks`): `{gid | seq i64}* | count u32`;
    /// empty when there are none.
    fn marks_block(&self) -> Vec<u8> {
        if self.marks.is_empty() {
            return Vec::new();
        }
        let mut block = Vec::with_capacity(self.marks.len() * 24 + 4);
        for (gid, seq) in &self.marks {
            block.extend_from_slice(gid);
            block.extend_from_slice(&seq.to_le_bytes());
        }
        block.extend_from_slice(&(self.marks.len() as u32).to_le_bytes());
        block
    }
}

/// What one `take()` made, before it becomes Python objects.
struct Taken {
    marks: HashMap<[u8; 16], i64>,
    groups: [Grouper; 2],
    slow: Vec<Raw>,
    lanes: HashMap<u32, (u64, u64)>,
    samples: usize,
    oldest_ns: i64,
}

#[pyclass(module = "fleetlink._native")]
pub struct DataPlane {
    session: Mutex<Option<Session>>,
    shared: Arc<Shared>,
    subscribers: Mutex<HashMap<u32, Subscriber<()>>>,
    state: Mutex<State>,
    pace: Mutex<Pace>,
}

#[pymethods]
impl DataPlane {
    /// `DataPlane(config_file, overrides, max_items, max_bytes, max_sources, coalesce_s,
    /// busy_coalesce_s)`: open a
    /// Zenoh session from a JSON5 config file (or the defaults) with `overrides` (key, JSON5
    /// value) inserted, and an intake bounded by `max_items` samples and `max_bytes` bytes. A
    /// sample that finds the receive thread idle makes it wait `coalesce_s` before reading on
    /// (`busy_coalesce_s` while samples arrive at the busy rate of `take`; 0: never), so that the
    /// samples that follow are read together.
    #[new]
    #[pyo3(signature = (config_file, overrides, max_items, max_bytes, max_sources=65536, coalesce_s=0.0, busy_coalesce_s=0.0))]
    fn new(
        py: Python<'_>,
        config_file: Option<String>,
        overrides: Vec<(String, String)>,
        max_items: usize,
        max_bytes: usize,
        max_sources: usize,
        coalesce_s: f64,
        busy_coalesce_s: f64,
    ) -> PyResult<Self> {
        if !(0.0..=0.1).contains(&coalesce_s) || !(0.0..=0.1).contains(&busy_coalesce_s) {
            return Err(PyValueError::new_err("coalesce_s and busy_coalesce_s must be between 0 and 0.1"));
        }
        if max_items == 0 || max_bytes == 0 {
            return Err(PyValueError::new_err("intake bounds must be positive"));
        }
        let mut config = match config_file {
            Some(path) => Config::from_file(&path).map_err(|e| PyValueError::new_err(format!("zenoh config {path}: {e}")))?,
            None => Config::default(),
        };
        for (key, value) in overrides {
            config
                .insert_json5(&key, &value)
                .map_err(|e| PyValueError::new_err(format!("zenoh config {key}={value}: {e}")))?;
        }
        let session = py.detach(|| zenoh::open(config).wait()).map_err(zerr)?;
        Ok(DataPlane {
            session: Mutex::new(Some(session)),
            shared: Arc::new(Shared {
                queue: Mutex::new(Queue {
                    items: VecDeque::new(),
                    bytes: 0,
                    high_water: 0,
                    woken: false,
                    want: 0,
                    dropped_by: Drops::new(MAX_DROP_SOURCES),
                }),
                ready: Condvar::new(),
                max_items,
                max_bytes,
                dropped: AtomicU64::new(0),
                dropped_bytes: AtomicU64::new(0),
                taken: AtomicU64::new(0),
                coalesce: Duration::from_secs_f64(coalesce_s),
                busy_coalesce: Duration::from_secs_f64(busy_coalesce_s),
                last_ns: AtomicU64::new(0),
                started: Instant::now(),
                coalesced: AtomicU64::new(0),
                busy: AtomicBool::new(false),
            }),
            subscribers: Mutex::new(HashMap::new()),
            state: Mutex::new(State {
                programs: HashMap::new(),
                plans: HashMap::new(),
                seqs: SeqTracker::new(max_sources),
                intake_drops: Drops::new(max_sources),
                keys: HashMap::new(),
                subs: HashMap::new(),
                topics: HashMap::new(),
            }),
            pace: Mutex::new(Pace { since: Instant::now(), count: 0, rate: 0.0 }),
        })
    }

    /// The Zenoh id of the data plane's session.
    fn zid(&self) -> PyResult<String> {
        let guard = self.session.lock().unwrap();
        let session = guard.as_ref().ok_or_else(|| PyRuntimeError::new_err("the data plane is closed"))?;
        Ok(session.zid().to_string())
    }

    /// Receive `key_expr` into the intake, under `sub_id` (its counters); `topic` names it.
    fn subscribe(&self, py: Python<'_>, sub_id: u32, key_expr: String, topic: String) -> PyResult<()> {
        let session = {
            let guard = self.session.lock().unwrap();
            guard.as_ref().ok_or_else(|| PyRuntimeError::new_err("the data plane is closed"))?.clone()
        };
        let atomics = {
            let mut state = self.state.lock().unwrap();
            state.topics.insert(sub_id, topic);
            state.subs.entry(sub_id).or_insert_with(|| Arc::new(SubAtomics::default())).clone()
        };
        let shared = self.shared.clone();
        let subscriber = py
            .detach(move || {
                session
                    .declare_subscriber(key_expr)
                    .callback(move |sample| {
                        let raw = Raw {
                            sub: sub_id,
                            key: sample.key_expr().as_str().to_owned(),
                            payload: sample.payload().to_bytes().into_owned(),
                            attachment: sample.attachment().map(|a| a.to_bytes().into_owned()),
                            received_ns: now_ns(),
                        };
                        let woke = shared.woke();
                        shared.offer(raw, &atomics);
                        shared.coalesce(woke);
                    })
                    .wait()
            })
            .map_err(zerr)?;
        if let Some(old) = self.subscribers.lock().unwrap().insert(sub_id, subscriber) {
            py.detach(|| old.undeclare().wait()).map_err(zerr)?;
        }
        Ok(())
    }

    /// Stop receiving under `sub_id` (what is already in the intake is still taken).
    fn unsubscribe(&self, py: Python<'_>, sub_id: u32) -> PyResult<bool> {
        let removed = self.subscribers.lock().unwrap().remove(&sub_id);
        match removed {
            Some(sub) => {
                py.detach(|| sub.undeclare().wait()).map_err(zerr)?;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// Register a compiled CDR -> Avro layout under `program_id`.
    fn add_program(&self, program_id: u32, code: &[u8]) -> PyResult<()> {
        let program = Program::parse(code).map_err(PyValueError::new_err)?;
        self.state.lock().unwrap().programs.insert(program_id, Arc::new(program));
        Ok(())
    }

    /// How the samples of data key `key` become records: one lane per mapping,
    /// `(lane_id, program_id, head, tail, flags, delivery)`; `program_id` MISMATCH only counts;
    /// no lane at all: nothing maps the key (its samples are counted and dropped here). False
    /// when the plan was not kept (too many plans: the key stays on the Python path).
    fn set_plan(&self, key: String, lanes: Vec<(u32, u32, Vec<u8>, Vec<u8>, u8, u8)>) -> PyResult<bool> {
        let mut state = self.state.lock().unwrap();
        let mut built = Vec::with_capacity(lanes.len());
        for (id, program_id, head, tail, flags, delivery) in lanes {
            if delivery > 1 {
                return Err(PyValueError::new_err(format!("delivery class {delivery} is not 0 or 1")));
            }
            if program_id != MISMATCH && head.len() != 10 {
                return Err(PyValueError::new_err("a lane's head is C3 01 and an 8-byte fingerprint"));
            }
            let program = if program_id == MISMATCH {
                None
            } else {
                Some(
                    state
                        .programs
                        .get(&program_id)
                        .cloned()
                        .ok_or_else(|| PyValueError::new_err(format!("no program {program_id}")))?,
                )
            };
            built.push(Lane { id, program, head, tail, flags, delivery });
        }
        if state.plans.len() >= MAX_PLANS && !state.plans.contains_key(&key) {
            return Ok(false);
        }
        state.plans.insert(key, Arc::new(Plan { lanes: built }));
        Ok(true)
    }

    /// Forget every plan (the mapping table changed): keys go to Python until planned again.
    fn clear_plans(&self) {
        self.state.lock().unwrap().plans.clear();
    }

    fn plans(&self) -> usize {
        self.state.lock().unwrap().plans.len()
    }

    /// Wake a waiting `take()` (something else needs the processing thread).
    fn wake(&self) {
        let mut q = self.shared.queue.lock().unwrap();
        q.woken = true;
        drop(q);
        self.shared.ready.notify_all();
    }

    /// Up to `max_samples` samples, waiting at most `timeout_s` for the first and then up to
    /// `collect_s` for more, and up to `busy_collect_s` in all while samples arrive at `busy_rate`
    /// a second or more (`wait_and_drain`). Returns
    /// `(groups, slow, lanes, samples, oldest_received_ns, marks)`: `groups` a list of
    /// `(delivery, group)` (`fleetlink.wire.groups`; at most `group_records` records and, beyond
    /// one, `group_bytes` bytes each), `slow` the raw samples for the Python path
    /// `(sub_id, key, payload, attachment | None, received_ns)`, `lanes` the
    /// `(lane_id, received, emitted)` counts of this call, `marks` a marks block
    /// (`fleetlink.edge.spool.marks`, empty when none): the last `(gid, seq)` of each
    /// publisher whose samples became records here or went to the Python path (a duplicate never
    /// lowers a mark).
    #[pyo3(signature = (max_samples, timeout_s, max_value_bytes, group_records=2000, group_bytes=1048576, collect_s=0.0, busy_rate=0.0, busy_collect_s=0.0))]
    fn take<'py>(
        &self,
        py: Python<'py>,
        max_samples: usize,
        timeout_s: f64,
        max_value_bytes: usize,
        group_records: u32,
        group_bytes: usize,
        collect_s: f64,
        busy_rate: f64,
        busy_collect_s: f64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let mut taken = py.detach(|| {
            let (raws, drops) =
                self.wait_and_drain(max_samples.max(1), timeout_s, collect_s, busy_rate, busy_collect_s);
            self.process(raws, drops, max_value_bytes, group_records, group_bytes)
        });
        let marks = PyBytes::new(py, &taken.marks_block());
        let mut groups: Vec<(u8, Bound<'py, PyBytes>)> = Vec::new();
        for (delivery, grouper) in taken.groups.iter_mut().enumerate() {
            grouper.close();
            for group in &grouper.done {
                groups.push((delivery as u8, PyBytes::new(py, group)));
            }
        }
        let slow: Vec<(u32, String, Bound<'py, PyBytes>, Option<Bound<'py, PyBytes>>, i64)> = taken
            .slow
            .into_iter()
            .map(|r| {
                (
                    r.sub,
                    r.key,
                    PyBytes::new(py, &r.payload),
                    r.attachment.as_ref().map(|a| PyBytes::new(py, a)),
                    r.received_ns,
                )
            })
            .collect();
        let lanes: Vec<(u32, u64, u64)> = taken.lanes.into_iter().map(|(id, (r, e))| (id, r, e)).collect();
        (groups, slow, lanes, taken.samples, taken.oldest_ns, marks).into_pyobject(py).map(|t| t.into_any())
    }

    /// The intake's counters.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let q = self.shared.queue.lock().unwrap();
        d.set_item("queued", q.items.len())?;
        d.set_item("queued_bytes", q.bytes)?;
        d.set_item("high_water", q.high_water)?;
        d.set_item("oldest_ns", q.items.front().map_or(0, |r| r.received_ns))?;
        drop(q);
        d.set_item("dropped", self.shared.dropped.load(Ordering::Relaxed))?;
        d.set_item("dropped_bytes", self.shared.dropped_bytes.load(Ordering::Relaxed))?;
        d.set_item("taken", self.shared.taken.load(Ordering::Relaxed))?;
        d.set_item("coalesced", self.shared.coalesced.load(Ordering::Relaxed))?;
        d.set_item("max_items", self.shared.max_items)?;
        d.set_item("max_bytes", self.shared.max_bytes)?;
        d.set_item("subscriptions", self.subscribers.lock().unwrap().len())?;
        Ok(d)
    }

    /// Per subscription: `(received, dropped at the intake)`.
    fn sub_stats(&self) -> HashMap<u32, (u64, u64)> {
        let state = self.state.lock().unwrap();
        state
            .subs
            .iter()
            .map(|(id, a)| (*id, (a.received.load(Ordering::Relaxed), a.dropped.load(Ordering::Relaxed))))
            .collect()
    }

    /// Per data key taken: `(received, gaps, missing, duplicates, lost_at_restart, unmapped)`
    /// (keys beyond the first 65,536 are counted under `*`).
    fn key_stats(&self) -> HashMap<String, (u64, u64, u64, u64, u64, u64)> {
        let state = self.state.lock().unwrap();
        state
            .keys
            .iter()
            .map(|(k, c)| (k.clone(), (c.received, c.gaps, c.missing, c.duplicates, c.lost_at_restart, c.unmapped)))
            .collect()
    }

    /// Restore what a previous run spooled last per publisher: `(gid, seq)` pairs. The next
    /// sample of each tells (counted as `lost_at_restart`) what was lost in between.
    fn seed(&self, marks: Vec<(Vec<u8>, i64)>) -> PyResult<()> {
        let mut state = self.state.lock().unwrap();
        for (gid, seq) in marks {
            let gid: [u8; 16] = gid.as_slice().try_into().map_err(|_| PyValueError::new_err("a GID has 16 bytes"))?;
            state.seqs.seed(&gid, seq);
        }
        Ok(())
    }

    /// The last sequence number seen from a publisher GID (16 bytes), if any.
    fn last_seq(&self, gid: &[u8]) -> Option<i64> {
        let gid: [u8; 16] = gid.try_into().ok()?;
        self.state.lock().unwrap().seqs.last(&gid)
    }

    /// Undeclare every subscription and close the session. Idempotent.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let subs: Vec<Subscriber<()>> = self.subscribers.lock().unwrap().drain().map(|(_, s)| s).collect();
        let session = self.session.lock().unwrap().take();
        py.detach(|| {
            for sub in subs {
                let _ = sub.undeclare().wait();
            }
            if let Some(s) = session {
                let _ = s.close().wait();
            }
        });
        self.wake();
        Ok(())
    }
}

impl DataPlane {
    /// Wait up to `timeout_s` for a first sample, then up to `collect_s` more for company (so that
    /// a steady trickle is taken a few ms' worth at a time, not one sample at a time), and take
    /// at most `max`. While samples arrive at `busy_rate` a second or more (measured over the
    /// takes of the last 100 ms or so, so a burst at a low rate does not count), a take's fixed
    /// cost (waking the threads that handle what it spools) outweighs a few ms of latency:
    /// collect until `busy_collect_s` after the first sample. The sample that makes `max` ends
    /// the wait (a burst is taken `max` at a time, not a window's worth at a time).
    fn wait_and_drain(
        &self,
        max: usize,
        timeout_s: f64,
        collect_s: f64,
        busy_rate: f64,
        busy_collect_s: f64,
    ) -> (Vec<Raw>, Drops) {
        let busy = busy_rate > 0.0 && self.pace.lock().unwrap().rate >= busy_rate;
        self.shared.busy.store(busy, Ordering::Relaxed);
        let deadline = Instant::now() + Duration::from_secs_f64(timeout_s.max(0.0));
        let mut q = self.shared.queue.lock().unwrap();
        while q.items.is_empty() && !q.woken {
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            q = self.shared.ready.wait_timeout(q, deadline - now).unwrap().0;
        }
        if !q.items.is_empty() && !q.woken && collect_s > 0.0 {
            let window = if busy { collect_s.max(busy_collect_s) } else { collect_s };
            let until = Instant::now() + Duration::from_secs_f64(window);
            q.want = max;
            while q.items.len() < max && !q.woken {
                let now = Instant::now();
                if now >= until {
                    break;
                }
                q = self.shared.ready.wait_timeout(q, until - now).unwrap().0;
            }
            q.want = 0;
        }
        q.woken = false;
        let n = q.items.len().min(max);
        let raws: Vec<Raw> = q.items.drain(..n).collect();
        let freed: usize = raws.iter().map(Raw::size).sum();
        q.bytes -= freed;
        let drops = std::mem::replace(&mut q.dropped_by, Drops::new(MAX_DROP_SOURCES));
        drop(q);
        self.shared.taken.fetch_add(raws.len() as u64, Ordering::Relaxed);
        self.pace.lock().unwrap().note(raws.len());
        (raws, drops)
    }

    fn process(
        &self,
        raws: Vec<Raw>,
        drops: Drops,
        max_value_bytes: usize,
        group_records: u32,
        group_bytes: usize,
    ) -> Taken {
        let mut taken = Taken {
            marks: HashMap::new(),
            groups: [Grouper::new(group_records, group_bytes), Grouper::new(group_records, group_bytes)],
            slow: Vec::new(),
            lanes: HashMap::new(),
            samples: raws.len(),
            oldest_ns: raws.first().map_or(0, |r| r.received_ns),
        };
        let mut state = self.state.lock().unwrap();
        if !drops.is_empty() {
            state.intake_drops.absorb(drops);
        }
        let mut bodies: Vec<Vec<u8>> = Vec::new();
        for raw in raws {
            let counts = if let Some(counts) = state.keys.get_mut(&raw.key) {
                counts
            } else if state.keys.len() < MAX_KEYS {
                state.keys.entry(raw.key.clone()).or_default()
            } else {
                state.keys.entry(OTHER_KEYS.to_owned()).or_default()
            };
            counts.received += 1;
            let parsed = raw.attachment.as_deref().and_then(attachment::parse);
            let Some(att) = parsed else {
                taken.slow.push(raw); // no or a broken attachment: the Python path says why
                continue;
            };
            let seen = state.seqs.observe(&att.gid, att.seq);
            let seen = state.intake_drops.settle(&att.gid, att.seq, seen); // drops counted at the intake
            let fresh = att.seq >= 0 && !matches!(seen, Seen::Duplicate);
            if !matches!(seen, Seen::First | Seen::Next) {
                let key = if state.keys.contains_key(&raw.key) { raw.key.as_str() } else { OTHER_KEYS };
                let counts = state.keys.get_mut(key).expect("counted above");
                match seen {
                    Seen::Gap(missing) => {
                        counts.gaps += 1;
                        counts.missing += missing;
                    }
                    Seen::LostAtRestart(missing) => counts.lost_at_restart += missing,
                    Seen::Duplicate => counts.duplicates += 1,
                    _ => {}
                }
            }
            let Some(plan) = state.plans.get(&raw.key).cloned() else {
                if fresh {
                    taken.mark(att.gid, att.seq);
                }
                taken.slow.push(raw);
                continue;
            };
            if plan.lanes.is_empty() {
                if fresh || att.seq < 0 {
                    let key = if state.keys.contains_key(&raw.key) { raw.key.as_str() } else { OTHER_KEYS };
                    state.keys.get_mut(key).expect("counted above").unmapped += 1;
                }
                continue;
            }
            if att.seq < 0 || !convert_all(&plan, &raw.payload, max_value_bytes, &mut bodies) {
                if fresh {
                    taken.mark(att.gid, att.seq);
                }
                taken.slow.push(raw);
                continue;
            }
            if fresh && plan.lanes.iter().any(|l| l.program.is_some()) {
                taken.mark(att.gid, att.seq);
            }
            let stamp = if att.source_ts_ns != 0 { att.source_ts_ns } else { raw.received_ns };
            let ts_ms = stamp.div_euclid(1_000_000);
            for (lane, body) in plan.lanes.iter().zip(bodies.iter()) {
                let entry = taken.lanes.entry(lane.id).or_insert((0, 0));
                entry.0 += 1;
                if lane.program.is_none() {
                    continue;
                }
                entry.1 += 1;
                let grouper = &mut taken.groups[lane.delivery as usize];
                let value_len = lane.head.len() + body.len();
                let payload_len = 13 + value_len + 8 + lane.tail.len();
                grouper.reserve(payload_len);
                grouper.note(&lane.head[2..]);
                let blob = &mut grouper.body;
                blob.extend_from_slice(&(payload_len as u32).to_le_bytes());
                blob.push(lane.flags | FLAG_SOURCE_SEQ);
                blob.extend_from_slice(&ts_ms.to_le_bytes());
                blob.extend_from_slice(&(value_len as u32).to_le_bytes());
                blob.extend_from_slice(&lane.head);
                blob.extend_from_slice(body);
                blob.extend_from_slice(&(att.seq as u64).to_le_bytes());
                blob.extend_from_slice(&lane.tail);
            }
        }
        taken
    }
}

/// Each lane's Avro body into `bodies` (one per lane, in order); false when one does not convert
/// or is too large (then the whole sample takes the Python path, so no lane emits twice).
fn convert_all(plan: &Plan, payload: &[u8], max_value_bytes: usize, bodies: &mut Vec<Vec<u8>>) -> bool {
    bodies.resize_with(plan.lanes.len(), Vec::new);
    let mut previous: Option<(&Arc<Program>, usize)> = None;
    for (i, lane) in plan.lanes.iter().enumerate() {
        bodies[i].clear();
        let Some(program) = &lane.program else { continue };
        if let Some((p, j)) = previous {
            if Arc::ptr_eq(p, program) {
                let (done, rest) = bodies.split_at_mut(i);
                rest[0].extend_from_slice(&done[j]);
                continue;
            }
        }
        if program.convert(payload, &mut bodies[i]).is_err() || lane.head.len() + bodies[i].len() > max_value_bytes {
            return false;
        }
        previous = Some((program, i));
    }
    true
}
