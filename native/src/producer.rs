//! The uplink's per-record path: a WAN batch's records into Kafka without the GIL.
//!
//! `scan` parses the record groups of a decompressed batch body (`fleetlink.wire.groups`) once
//! and reports each distinct *tail* (topic, key, headers: the same for every record of one robot
//! and mapping) so that the Python side decides per tail, not per record (the sender's
//! identity, the topic policy, the schema ids). `NativeProducer.produce` then hands every
//! record of an approved tail to librdkafka (`rd_kafka_produceva`, copying; the single-object
//! header swapped for the Confluent one), keeps a count per batch, and reports each batch once
//! every record has its delivery report (`wait_done`). Records of other tails come back as
//! indices for the Python path, as do records whose delivery failed.

use std::collections::{HashMap, VecDeque};
use std::ffi::{c_int, c_void, CString};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::rdkafka::{self, Api, Message, Vu};

const FLAG_RAW_VALUE: u8 = 0x01;
const FLAG_NULL_KEY: u8 = 0x02;
const FLAG_SOURCE_SEQ: u8 = 0x04;
const SEQ_HEADER: &[u8] = b"fleetlink.seq\0";

struct Tail {
    topic_id: u32,
    topic: String,
    topic_c: CString,
    key: Vec<u8>,
    headers: Vec<(CString, Vec<u8>)>,
}

struct RecordRef {
    seq: u64,
    tail: u32,
    flags: u8,
    timestamp_ms: i64,
    value: (usize, usize),
    source_seq: Option<u64>,
    span: (usize, usize),
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    end: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if self.end - self.pos < n {
            return Err(format!("truncated {what} at byte {}", self.pos));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u16(&mut self, what: &str) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().unwrap()))
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    fn text(&mut self, what: &str) -> Result<String, String> {
        let n = self.u16(what)? as usize;
        let b = self.take(n, what)?;
        String::from_utf8(b.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
    fn blob(&mut self, what: &str) -> Result<&'a [u8], String> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }
}

fn parse_tail(data: &[u8], pos: usize, end: usize) -> Result<Tail, String> {
    let mut r = Reader { data, pos, end };
    let topic = r.text("Kafka topic")?;
    let key = r.blob("record key")?.to_vec();
    let n = r.u16("header count")?;
    let mut headers = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let name = r.text("header name")?;
        let value = r.blob("header value")?.to_vec();
        let name = CString::new(name).map_err(|_| "a header name holds a NUL byte".to_string())?;
        headers.push((name, value));
    }
    if r.pos != end {
        return Err(format!("{} trailing bytes after the record", end - r.pos));
    }
    let topic_c = CString::new(topic.clone()).map_err(|_| "the topic holds a NUL byte".to_string())?;
    Ok(Tail { topic_id: 0, topic, topic_c, key, headers })
}

/// What a batch holds for one Kafka topic: the unit the uplink decides on (policy, schema ids).
struct TopicSum {
    name: String,
    records: u32,
    raw: u32,
    fingerprints: Vec<[u8; 8]>,
}

/// A batch body parsed once: its records by reference, its tails by value.
#[pyclass(module = "fleetlink._native", frozen)]
pub struct ScannedBatch {
    body: Vec<u8>,
    records: Vec<RecordRef>,
    tails: Vec<Tail>,
    topics: Vec<TopicSum>,
}

#[pymethods]
impl ScannedBatch {
    /// Parse the groups of a decompressed batch body from byte `start` (after the schemas).
    #[staticmethod]
    fn scan(py: Python<'_>, body: Vec<u8>, start: usize) -> PyResult<ScannedBatch> {
        py.detach(|| scan(body, start)).map_err(PyValueError::new_err)
    }

    /// Records in the batch.
    fn __len__(&self) -> usize {
        self.records.len()
    }

    /// `(seq, payload)` of record `index`: its bytes as the edge encoded them.
    fn record<'py>(&self, py: Python<'py>, index: usize) -> PyResult<(u64, Bound<'py, PyBytes>)> {
        let r = self.records.get(index).ok_or_else(|| PyValueError::new_err("no such record"))?;
        Ok((r.seq, PyBytes::new(py, &self.body[r.span.0..r.span.1])))
    }

    /// Per distinct Kafka topic: `(topic, records, raw records, fingerprints)`; a topic's index
    /// in this list is its id in `senders` and `NativeProducer.produce`.
    fn topics<'py>(&self, py: Python<'py>) -> Vec<(String, u32, u32, Vec<Bound<'py, PyBytes>>)> {
        self.topics
            .iter()
            .map(|t| {
                let fps = t.fingerprints.iter().map(|fp| PyBytes::new(py, fp)).collect();
                (t.name.clone(), t.records, t.raw, fps)
            })
            .collect()
    }

    /// Per distinct (topic, values of the headers `names`): `(topic id, those headers, seq of
    /// the first record)`. An honest edge gives one entry per topic however many robots and
    /// keys its records have: what the sender check reads, without a Python object per tail.
    #[allow(clippy::type_complexity)]
    fn senders<'py>(
        &self,
        py: Python<'py>,
        names: Vec<String>,
    ) -> Vec<(u32, Vec<(String, Bound<'py, PyBytes>)>, u64)> {
        let mut first_seq: HashMap<u32, u64> = HashMap::new();
        for r in &self.records {
            first_seq.entry(r.tail).or_insert(r.seq);
        }
        let mut seen: HashMap<(u32, Vec<(&[u8], &[u8])>), usize> = HashMap::new();
        let mut out: Vec<(u32, Vec<(String, Bound<'py, PyBytes>)>, u64)> = Vec::new();
        for (index, tail) in self.tails.iter().enumerate() {
            let picked: Vec<(&[u8], &[u8])> = tail
                .headers
                .iter()
                .filter(|(n, _)| names.iter().any(|want| want.as_bytes() == n.as_bytes()))
                .map(|(n, v)| (n.as_bytes(), v.as_slice()))
                .collect();
            let seq = first_seq.get(&(index as u32)).copied().unwrap_or(0);
            match seen.get(&(tail.topic_id, picked.clone())) {
                Some(&at) => {
                    if seq < out[at].2 {
                        out[at].2 = seq;
                    }
                }
                None => {
                    let headers = picked
                        .iter()
                        .map(|(n, v)| (String::from_utf8_lossy(n).into_owned(), PyBytes::new(py, v)))
                        .collect();
                    seen.insert((tail.topic_id, picked), out.len());
                    out.push((tail.topic_id, headers, seq));
                }
            }
        }
        out
    }

    /// How many records have a seq at or below `seq`.
    fn at_or_below(&self, seq: u64) -> usize {
        self.records.iter().filter(|r| r.seq <= seq).count()
    }

    /// The seq of the last record.
    fn last_seq(&self) -> u64 {
        self.records.last().map(|r| r.seq).unwrap_or(0)
    }

    /// Records per topic whose seq is not in `dead` (what Kafka acknowledged of an answered batch).
    fn acked_counts(&self, dead: Vec<u64>) -> HashMap<String, u64> {
        let dead: std::collections::HashSet<u64> = dead.into_iter().collect();
        let mut counts = vec![0u64; self.topics.len()];
        for r in &self.records {
            if !dead.contains(&r.seq) {
                counts[self.tails[r.tail as usize].topic_id as usize] += 1;
            }
        }
        self.topics.iter().zip(counts).filter(|(_, n)| *n > 0).map(|(t, n)| (t.name.clone(), n)).collect()
    }

    /// Per topic among `topics` (ids): `(topic, delivered, failed)`, failed being the records
    /// whose index is in `failed` (delivery reports of a natively produced part); records at or
    /// below `min_seq` were not produced.
    #[pyo3(signature = (topics, failed, min_seq=0))]
    fn delivery_counts(&self, topics: Vec<u32>, failed: Vec<u32>, min_seq: u64) -> Vec<(String, u64, u64)> {
        let failed: std::collections::HashSet<u32> = failed.into_iter().collect();
        let mut counts: HashMap<u32, (u64, u64)> = topics.iter().map(|t| (*t, (0, 0))).collect();
        for (i, r) in self.records.iter().enumerate() {
            if r.seq <= min_seq {
                continue;
            }
            if let Some(c) = counts.get_mut(&self.tails[r.tail as usize].topic_id) {
                if failed.contains(&(i as u32)) {
                    c.1 += 1;
                } else {
                    c.0 += 1;
                }
            }
        }
        let mut out: Vec<(String, u64, u64)> =
            counts.into_iter().map(|(t, (ok, bad))| (self.topics[t as usize].name.clone(), ok, bad)).collect();
        out.sort();
        out
    }
}

fn scan(body: Vec<u8>, start: usize) -> Result<ScannedBatch, String> {
    let mut records = Vec::new();
    let mut tails: Vec<Tail> = Vec::new();
    let mut tail_ids: HashMap<Vec<u8>, u32> = HashMap::new();
    let mut topics: Vec<TopicSum> = Vec::new();
    let mut topic_ids: HashMap<String, u32> = HashMap::new();
    {
        let data = &body[..];
        let mut r = Reader { data, pos: start.min(data.len()), end: data.len() };
        let n_groups = r.u32("group count")?;
        if n_groups == 0 {
            return Err("a batch needs at least one record".into());
        }
        let mut following: u64 = 0;
        for _ in 0..n_groups {
            let mut seq = r.u64("group seq")?;
            if seq < following {
                return Err(format!("record seqs must increase: a group starts at {seq}, below {following}"));
            }
            let glen = r.u32("group length")? as usize;
            let gstart = r.pos;
            let group = r.take(glen, "group")?;
            let mut g = Reader { data, pos: gstart, end: gstart + group.len() };
            let count = g.u32("group count")?;
            let nfp = g.u16("fingerprint count")? as usize;
            g.take(8 * nfp, "fingerprints")?;
            if count == 0 {
                return Err("a group holds at least one record".into());
            }
            for _ in 0..count {
                let len = g.u32("record length")? as usize;
                let rstart = g.pos;
                let rec = g.take(len, "record")?;
                let mut p = Reader { data, pos: rstart, end: rstart + rec.len() };
                let flags = p.take(1, "record flags")?[0];
                if flags & !(FLAG_RAW_VALUE | FLAG_NULL_KEY | FLAG_SOURCE_SEQ) != 0 {
                    return Err(format!("unknown record flags 0x{flags:02x}"));
                }
                let ts = i64::from_le_bytes(p.take(8, "timestamp")?.try_into().unwrap());
                let vlen = p.u32("value length")? as usize;
                let vstart = p.pos;
                p.take(vlen, "record value")?;
                let source_seq = if flags & FLAG_SOURCE_SEQ != 0 { Some(p.u64("source seq")?) } else { None };
                let tail_bytes = &data[p.pos..p.end];
                let tail_id = match tail_ids.get(tail_bytes) {
                    Some(id) => *id,
                    None => {
                        let mut tail = parse_tail(data, p.pos, p.end)?;
                        tail.topic_id = match topic_ids.get(&tail.topic) {
                            Some(id) => *id,
                            None => {
                                topics.push(TopicSum {
                                    name: tail.topic.clone(),
                                    records: 0,
                                    raw: 0,
                                    fingerprints: vec![],
                                });
                                topic_ids.insert(tail.topic.clone(), (topics.len() - 1) as u32);
                                (topics.len() - 1) as u32
                            }
                        };
                        tails.push(tail);
                        let id = (tails.len() - 1) as u32;
                        tail_ids.insert(tail_bytes.to_vec(), id);
                        id
                    }
                };
                let tail = &tails[tail_id as usize];
                if flags & FLAG_NULL_KEY != 0 && !tail.key.is_empty() {
                    return Err("record flagged with a null key carries key bytes".into());
                }
                let topic = &mut topics[tail.topic_id as usize];
                topic.records += 1;
                if flags & FLAG_RAW_VALUE != 0 {
                    topic.raw += 1;
                } else if vlen >= 10 && data[vstart] == 0xC3 && data[vstart + 1] == 0x01 {
                    let fp: [u8; 8] = data[vstart + 2..vstart + 10].try_into().unwrap();
                    if !topic.fingerprints.contains(&fp) {
                        topic.fingerprints.push(fp);
                    }
                }
                records.push(RecordRef {
                    seq,
                    tail: tail_id,
                    flags,
                    timestamp_ms: ts,
                    value: (vstart, vstart + vlen),
                    source_seq,
                    span: (rstart, rstart + rec.len()),
                });
                seq += 1;
            }
            if g.pos != g.end {
                return Err(format!("{} bytes after the {count} records of a group", g.end - g.pos));
            }
            following = seq;
        }
        if r.pos != r.end {
            return Err(format!("{} unexpected trailing bytes after the batch", r.end - r.pos));
        }
    }
    Ok(ScannedBatch { body, records, tails, topics })
}

struct BatchState {
    remaining: usize,
    failures: Vec<(u32, c_int)>,
}

struct Shared {
    batches: Mutex<HashMap<u32, BatchState>>,
    done: Mutex<VecDeque<(u32, Vec<(u32, c_int)>)>>,
    ready: Condvar,
}

impl Shared {
    fn settle(&self, batch: u32, index: u32, err: c_int) {
        let mut batches = self.batches.lock().unwrap();
        let finished = match batches.get_mut(&batch) {
            Some(state) => {
                if err != 0 {
                    state.failures.push((index, err));
                }
                state.remaining -= 1;
                state.remaining == 0
            }
            None => false,
        };
        if finished {
            let state = batches.remove(&batch).unwrap();
            drop(batches);
            self.done.lock().unwrap().push_back((batch, state.failures));
            self.ready.notify_all();
        }
    }
}

unsafe extern "C" fn on_delivery(_rk: *mut c_void, msg: *const Message, opaque: *mut c_void) {
    let shared = &*(opaque as *const Shared);
    let msg = &*msg;
    let tag = msg.private as u64;
    shared.settle((tag >> 32) as u32, (tag & 0xFFFF_FFFF) as u32, msg.err);
}

struct Handle(*mut c_void);
unsafe impl Send for Handle {}
unsafe impl Sync for Handle {}

/// Hand one record to librdkafka, waiting while its queue is full; a record it refuses at once
/// is settled with that error.
fn hand_over(api: &Api, rk: &Handle, shared: &Shared, args: &[Vu], id: u32, index: u32) {
    loop {
        let err = unsafe { (api.produceva)(rk.0, args.as_ptr(), args.len() - 1) };
        if err.is_null() {
            return;
        }
        let code = unsafe { (api.error_code)(err) };
        unsafe { (api.error_destroy)(err) };
        if code == rdkafka::ERR_QUEUE_FULL {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        shared.settle(id, index, code);
        return;
    }
}

/// A librdkafka producer of its own (idempotent, `acks=all`: the config the Python side gives).
#[pyclass(module = "fleetlink._native")]
pub struct NativeProducer {
    api: Arc<Api>,
    rk: Arc<Handle>,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    poller: Mutex<Option<JoinHandle<()>>>,
    next_batch: Mutex<u32>,
}

impl NativeProducer {
    fn batch_id(&self) -> u32 {
        let mut next = self.next_batch.lock().unwrap();
        let id = *next;
        *next = next.wrapping_add(1).max(1);
        id
    }
}

#[pymethods]
impl NativeProducer {
    /// `NativeProducer(library_path, config)`: `config` as librdkafka properties.
    #[new]
    fn new(library: String, config: Vec<(String, String)>) -> PyResult<Self> {
        let api = Arc::new(Api::load(&library).map_err(PyRuntimeError::new_err)?);
        let shared = Arc::new(Shared { batches: Mutex::new(HashMap::new()), done: Mutex::new(VecDeque::new()), ready: Condvar::new() });
        let mut errstr = [0 as std::ffi::c_char; 512];
        let rk = unsafe {
            let conf = (api.conf_new)();
            for (k, v) in &config {
                let (ck, cv) = (CString::new(k.as_str())?, CString::new(v.as_str())?);
                if (api.conf_set)(conf, ck.as_ptr(), cv.as_ptr(), errstr.as_mut_ptr(), errstr.len()) != rdkafka::CONF_OK {
                    (api.conf_destroy)(conf);
                    let msg = std::ffi::CStr::from_ptr(errstr.as_ptr()).to_string_lossy().into_owned();
                    return Err(PyValueError::new_err(format!("{k}: {msg}")));
                }
            }
            (api.conf_set_dr_msg_cb)(conf, Some(on_delivery));
            (api.conf_set_opaque)(conf, Arc::as_ptr(&shared) as *mut c_void);
            let rk = (api.new)(rdkafka::PRODUCER, conf, errstr.as_mut_ptr(), errstr.len());
            if rk.is_null() {
                let msg = std::ffi::CStr::from_ptr(errstr.as_ptr()).to_string_lossy().into_owned();
                return Err(PyRuntimeError::new_err(format!("cannot create the Kafka producer: {msg}")));
            }
            rk
        };
        let rk = Arc::new(Handle(rk));
        let stop = Arc::new(AtomicBool::new(false));
        let poller = {
            let (api, rk, stop) = (api.clone(), rk.clone(), stop.clone());
            std::thread::Builder::new()
                .name("kafka-native-poll".into())
                .spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        unsafe { (api.poll)(rk.0, 100) };
                    }
                })
                .map_err(|e| PyRuntimeError::new_err(e.to_string()))?
        };
        Ok(NativeProducer { api, rk, shared, stop, poller: Mutex::new(Some(poller)), next_batch: Mutex::new(1) })
    }

    /// Produce the records of `batch` whose topic is in `topics` (ids, see `ScannedBatch.topics`)
    /// and whose value is raw or has a Confluent header in `heads` (`(topic, fingerprint) -> 5
    /// bytes`). Returns
    /// `(batch_id, produced, others)`: `others` the indices of the records left to Python.
    /// Waits (the GIL released) while librdkafka's queue is full.
    ///
    /// Records at or below `min_seq` are in neither part: an exactly-once stream's records
    /// that Kafka already has.
    #[pyo3(signature = (batch, topics, heads, min_seq=0))]
    fn produce(
        &self,
        py: Python<'_>,
        batch: &Bound<'_, ScannedBatch>,
        topics: Vec<u32>,
        heads: HashMap<(u32, Vec<u8>), Vec<u8>>,
        min_seq: u64,
    ) -> PyResult<(u32, usize, Vec<u32>)> {
        let batch = batch.get();
        let id = self.batch_id();
        let ok: std::collections::HashSet<u32> = topics.into_iter().collect();
        let mut heads5: HashMap<(u32, [u8; 8]), [u8; 5]> = HashMap::new();
        for ((t, fp), h) in heads {
            if fp.len() == 8 && h.len() == 5 {
                heads5.insert((t, fp.try_into().unwrap()), h.try_into().unwrap());
            }
        }
        let mut mine = Vec::new();
        let mut others = Vec::new();
        for (i, r) in batch.records.iter().enumerate() {
            if r.seq <= min_seq {
                continue;
            }
            let topic = batch.tails[r.tail as usize].topic_id;
            let go = ok.contains(&topic)
                && (r.flags & FLAG_RAW_VALUE != 0 || {
                    let v = &batch.body[r.value.0..r.value.1];
                    v.len() >= 10 && v[0] == 0xC3 && v[1] == 0x01 && heads5.contains_key(&(topic, v[2..10].try_into().unwrap()))
                });
            if go {
                mine.push(i as u32);
            } else {
                others.push(i as u32);
            }
        }
        if mine.is_empty() {
            return Ok((id, 0, others));
        }
        self.shared.batches.lock().unwrap().insert(id, BatchState { remaining: mine.len(), failures: vec![] });
        let produced = mine.len();
        let (api, rk, shared) = (self.api.clone(), self.rk.clone(), self.shared.clone());
        py.detach(|| {
            let mut value = Vec::with_capacity(1024);
            let mut seqtext = Vec::with_capacity(20);
            let mut args: Vec<Vu> = Vec::with_capacity(32);
            for &i in &mine {
                let r = &batch.records[i as usize];
                let tail = &batch.tails[r.tail as usize];
                let v = &batch.body[r.value.0..r.value.1];
                value.clear();
                if r.flags & FLAG_RAW_VALUE != 0 {
                    value.extend_from_slice(v);
                } else {
                    let fp: [u8; 8] = v[2..10].try_into().unwrap();
                    value.extend_from_slice(&heads5[&(tail.topic_id, fp)]);
                    value.extend_from_slice(&v[10..]);
                }
                args.clear();
                args.push(Vu::cstr(rdkafka::VTYPE_TOPIC, tail.topic_c.as_ptr()));
                args.push(Vu::mem(rdkafka::VTYPE_VALUE, &value));
                if r.flags & FLAG_NULL_KEY == 0 {
                    args.push(Vu::mem(rdkafka::VTYPE_KEY, &tail.key));
                }
                args.push(Vu::i64(rdkafka::VTYPE_TIMESTAMP, r.timestamp_ms));
                args.push(Vu::int(rdkafka::VTYPE_MSGFLAGS, rdkafka::MSG_F_COPY));
                args.push(Vu::ptr(rdkafka::VTYPE_OPAQUE, (((id as u64) << 32) | i as u64) as *mut c_void));
                for (name, val) in &tail.headers {
                    args.push(Vu::header(name.as_ptr(), val));
                }
                if let Some(s) = r.source_seq {
                    seqtext.clear();
                    seqtext.extend_from_slice(s.to_string().as_bytes());
                    args.push(Vu::header(SEQ_HEADER.as_ptr() as *const std::ffi::c_char, &seqtext));
                }
                args.push(Vu::int(rdkafka::VTYPE_END, 0));
                hand_over(&api, &rk, &shared, &args, id, i);
            }
        });
        Ok((id, produced, others))
    }

    /// Produce one record, reported as a batch of its own (`wait_done`); returns its batch id.
    #[pyo3(signature = (topic, key, value, headers, timestamp_ms))]
    fn produce_one(
        &self,
        py: Python<'_>,
        topic: &str,
        key: Option<Vec<u8>>,
        value: Vec<u8>,
        headers: Vec<(String, Vec<u8>)>,
        timestamp_ms: i64,
    ) -> PyResult<u32> {
        let id = self.batch_id();
        let topic_c = CString::new(topic)?;
        let names = headers.iter().map(|(n, _)| CString::new(n.as_str())).collect::<Result<Vec<_>, _>>()?;
        self.shared.batches.lock().unwrap().insert(id, BatchState { remaining: 1, failures: vec![] });
        let (api, rk, shared) = (self.api.clone(), self.rk.clone(), self.shared.clone());
        py.detach(|| {
            let mut args: Vec<Vu> = vec![
                Vu::cstr(rdkafka::VTYPE_TOPIC, topic_c.as_ptr()),
                Vu::mem(rdkafka::VTYPE_VALUE, &value),
            ];
            if let Some(k) = &key {
                args.push(Vu::mem(rdkafka::VTYPE_KEY, k));
            }
            args.push(Vu::i64(rdkafka::VTYPE_TIMESTAMP, timestamp_ms));
            args.push(Vu::int(rdkafka::VTYPE_MSGFLAGS, rdkafka::MSG_F_COPY));
            args.push(Vu::ptr(rdkafka::VTYPE_OPAQUE, ((id as u64) << 32) as *mut c_void));
            for (name, (_, val)) in names.iter().zip(&headers) {
                args.push(Vu::header(name.as_ptr(), val));
            }
            args.push(Vu::int(rdkafka::VTYPE_END, 0));
            hand_over(&api, &rk, &shared, &args, id, 0)
        });
        Ok(id)
    }

    /// A call of the transactional API (a producer made with a `transactional.id`): `op` one of
    /// `init`, `begin`, `commit`, `abort`. Returns None, or what failed: `(name, message, fatal,
    /// retriable, requires abort)`. Waits (the GIL released) up to `timeout_s`.
    #[allow(clippy::type_complexity)]
    fn transaction(
        &self,
        py: Python<'_>,
        op: &str,
        timeout_s: f64,
    ) -> PyResult<Option<(String, String, bool, bool, bool)>> {
        let (api, rk) = (self.api.clone(), self.rk.clone());
        let ms = (timeout_s * 1000.0) as c_int;
        let call: unsafe fn(&Api, *mut c_void, c_int) -> *mut c_void = match op {
            "init" => |a, rk, ms| unsafe { (a.init_transactions)(rk, ms) },
            "begin" => |a, rk, _| unsafe { (a.begin_transaction)(rk) },
            "commit" => |a, rk, ms| unsafe { (a.commit_transaction)(rk, ms) },
            "abort" => |a, rk, ms| unsafe { (a.abort_transaction)(rk, ms) },
            _ => return Err(PyValueError::new_err(format!("no transaction call {op:?}"))),
        };
        let failed = py.detach(|| api.take_error(unsafe { call(&api, rk.0, ms) }));
        Ok(failed.map(|e| (e.name, e.message, e.fatal, e.retriable, e.requires_abort)))
    }

    /// Batches whose every record has its delivery report: `(batch_id, failures)`, failures as
    /// `(index, error code, error name, message)`; waits up to `timeout_s` for one.
    fn wait_done(&self, py: Python<'_>, timeout_s: f64) -> Vec<(u32, Vec<(u32, i32, String, String)>)> {
        let done: Vec<(u32, Vec<(u32, c_int)>)> = py.detach(|| {
            let deadline = Instant::now() + Duration::from_secs_f64(timeout_s.max(0.0));
            let mut q = self.shared.done.lock().unwrap();
            while q.is_empty() {
                let now = Instant::now();
                if now >= deadline || self.stop.load(Ordering::Relaxed) {
                    break;
                }
                q = self.shared.ready.wait_timeout(q, deadline - now).unwrap().0;
            }
            q.drain(..).collect()
        });
        done.into_iter()
            .map(|(id, failures)| {
                let failures = failures
                    .into_iter()
                    .map(|(i, code)| (i, code as i32, self.api.err_name(code), self.api.err_str(code)))
                    .collect();
                (id, failures)
            })
            .collect()
    }

    /// Records handed over and not yet delivered.
    fn in_flight(&self) -> i64 {
        unsafe { (self.api.outq_len)(self.rk.0) as i64 }
    }

    /// Wait up to `timeout_s` for every record to be delivered; returns how many are not.
    fn flush(&self, py: Python<'_>, timeout_s: f64) -> i64 {
        let (api, rk) = (self.api.clone(), self.rk.clone());
        py.detach(|| unsafe {
            (api.flush)(rk.0, (timeout_s * 1000.0) as c_int);
            (api.outq_len)(rk.0) as i64
        })
    }

    /// Stop polling and destroy the producer (what was not delivered is reported as failed).
    fn close(&self, py: Python<'_>) {
        let poller = self.poller.lock().unwrap().take();
        if let Some(poller) = poller {
            let (api, rk, stop) = (self.api.clone(), self.rk.clone(), self.stop.clone());
            py.detach(move || {
                unsafe { (api.flush)(rk.0, 1000) };
                stop.store(true, Ordering::Relaxed);
                let _ = poller.join();
                unsafe { (api.destroy)(rk.0) };
            });
            self.shared.ready.notify_all();
        }
    }
}
