//! The parts of librdkafka's C API the uplink's native producer uses, loaded at run time from the
//! very library confluent-kafka loaded (`fleetlink.uplink.native_producer` finds its path): one
//! librdkafka in the process, with whatever it was built with (TLS, SASL), and nothing to compile.

use std::ffi::{c_char, c_int, c_void, CStr};

use libloading::Library;

pub const PRODUCER: c_int = 0;
pub const CONF_OK: c_int = 0;
pub const ERR_QUEUE_FULL: c_int = -184;
pub const MSG_F_COPY: c_int = 0x2;

pub const VTYPE_END: c_int = 0;
pub const VTYPE_TOPIC: c_int = 1;
pub const VTYPE_VALUE: c_int = 4;
pub const VTYPE_KEY: c_int = 5;
pub const VTYPE_OPAQUE: c_int = 6;
pub const VTYPE_MSGFLAGS: c_int = 7;
pub const VTYPE_TIMESTAMP: c_int = 8;
pub const VTYPE_HEADER: c_int = 9;

/// `rd_kafka_message_t`.
#[repr(C)]
pub struct Message {
    pub err: c_int,
    pub rkt: *mut c_void,
    pub partition: i32,
    pub payload: *mut c_void,
    pub len: usize,
    pub key: *mut c_void,
    pub key_len: usize,
    pub offset: i64,
    pub private: *mut c_void,
}

#[repr(C)]
#[derive(Clone, Copy)]
pub struct VuMem {
    pub ptr: *const c_void,
    pub size: usize,
}

#[repr(C)]
#[derive(Clone, Copy)]
pub struct VuHeader {
    pub name: *const c_char,
    pub val: *const c_void,
    pub size: isize,
}

#[repr(C)]
#[derive(Clone, Copy)]
pub union VuValue {
    pub cstr: *const c_char,
    pub i: c_int,
    pub i64v: i64,
    pub mem: VuMem,
    pub header: VuHeader,
    pub ptr: *mut c_void,
    pub pad: [u8; 64],
}

/// `rd_kafka_vu_t`: one typed argument of `rd_kafka_produceva`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct Vu {
    pub vtype: c_int,
    pub u: VuValue,
}

impl Vu {
    pub fn cstr(vtype: c_int, s: *const c_char) -> Vu {
        Vu { vtype, u: VuValue { cstr: s } }
    }
    pub fn mem(vtype: c_int, data: &[u8]) -> Vu {
        Vu { vtype, u: VuValue { mem: VuMem { ptr: data.as_ptr() as *const c_void, size: data.len() } } }
    }
    pub fn int(vtype: c_int, i: c_int) -> Vu {
        Vu { vtype, u: VuValue { i } }
    }
    pub fn i64(vtype: c_int, v: i64) -> Vu {
        Vu { vtype, u: VuValue { i64v: v } }
    }
    pub fn ptr(vtype: c_int, p: *mut c_void) -> Vu {
        Vu { vtype, u: VuValue { ptr: p } }
    }
    pub fn header(name: *const c_char, val: &[u8]) -> Vu {
        Vu {
            vtype: VTYPE_HEADER,
            u: VuValue { header: VuHeader { name, val: val.as_ptr() as *const c_void, size: val.len() as isize } },
        }
    }
}

pub type DeliveryCallback = unsafe extern "C" fn(*mut c_void, *const Message, *mut c_void);

/// The functions, resolved once; `_lib` keeps the library mapped.
pub struct Api {
    _lib: Library,
    pub conf_new: unsafe extern "C" fn() -> *mut c_void,
    pub conf_set: unsafe extern "C" fn(*mut c_void, *const c_char, *const c_char, *mut c_char, usize) -> c_int,
    pub conf_set_dr_msg_cb: unsafe extern "C" fn(*mut c_void, Option<DeliveryCallback>),
    pub conf_set_opaque: unsafe extern "C" fn(*mut c_void, *mut c_void),
    pub conf_destroy: unsafe extern "C" fn(*mut c_void),
    pub new: unsafe extern "C" fn(c_int, *mut c_void, *mut c_char, usize) -> *mut c_void,
    pub produceva: unsafe extern "C" fn(*mut c_void, *const Vu, usize) -> *mut c_void,
    pub error_code: unsafe extern "C" fn(*const c_void) -> c_int,
    pub error_string: unsafe extern "C" fn(*const c_void) -> *const c_char,
    pub error_destroy: unsafe extern "C" fn(*mut c_void),
    pub poll: unsafe extern "C" fn(*mut c_void, c_int) -> c_int,
    pub flush: unsafe extern "C" fn(*mut c_void, c_int) -> c_int,
    pub outq_len: unsafe extern "C" fn(*mut c_void) -> c_int,
    pub destroy: unsafe extern "C" fn(*mut c_void),
    pub err2name: unsafe extern "C" fn(c_int) -> *const c_char,
    pub err2str: unsafe extern "C" fn(c_int) -> *const c_char,
    pub init_transactions: unsafe extern "C" fn(*mut c_void, c_int) -> *mut c_void,
    pub begin_transaction: unsafe extern "C" fn(*mut c_void) -> *mut c_void,
    pub commit_transaction: unsafe extern "C" fn(*mut c_void, c_int) -> *mut c_void,
    pub abort_transaction: unsafe extern "C" fn(*mut c_void, c_int) -> *mut c_void,
    pub error_name: unsafe extern "C" fn(*const c_void) -> *const c_char,
    pub error_is_fatal: unsafe extern "C" fn(*const c_void) -> c_int,
    pub error_is_retriable: unsafe extern "C" fn(*const c_void) -> c_int,
    pub error_txn_requires_abort: unsafe extern "C" fn(*const c_void) -> c_int,
}

/// A failed call of librdkafka's transactional API, read out of its `rd_kafka_error_t`.
pub struct TxnError {
    pub name: String,
    pub message: String,
    pub fatal: bool,
    pub retriable: bool,
    pub requires_abort: bool,
}

macro_rules! sym {
    ($lib:expr, $name:literal) => {
        *$lib.get(concat!($name, "\0").as_bytes()).map_err(|e| format!("{}: {e}", $name))?
    };
}

impl Api {
    /// Load librdkafka from `path` (already mapped by confluent-kafka: the same copy).
    pub fn load(path: &str) -> Result<Api, String> {
        unsafe {
            let lib = Library::new(path).map_err(|e| format!("cannot load {path}: {e}"))?;
            Ok(Api {
                conf_new: sym!(lib, "rd_kafka_conf_new"),
                conf_set: sym!(lib, "rd_kafka_conf_set"),
                conf_set_dr_msg_cb: sym!(lib, "rd_kafka_conf_set_dr_msg_cb"),
                conf_set_opaque: sym!(lib, "rd_kafka_conf_set_opaque"),
                conf_destroy: sym!(lib, "rd_kafka_conf_destroy"),
                new: sym!(lib, "rd_kafka_new"),
                produceva: sym!(lib, "rd_kafka_produceva"),
                error_code: sym!(lib, "rd_kafka_error_code"),
                error_string: sym!(lib, "rd_kafka_error_string"),
                error_destroy: sym!(lib, "rd_kafka_error_destroy"),
                poll: sym!(lib, "rd_kafka_poll"),
                flush: sym!(lib, "rd_kafka_flush"),
                outq_len: sym!(lib, "rd_kafka_outq_len"),
                destroy: sym!(lib, "rd_kafka_destroy"),
                err2name: sym!(lib, "rd_kafka_err2name"),
                err2str: sym!(lib, "rd_kafka_err2str"),
                init_transactions: sym!(lib, "rd_kafka_init_transactions"),
                begin_transaction: sym!(lib, "rd_kafka_begin_transaction"),
                commit_transaction: sym!(lib, "rd_kafka_commit_transaction"),
                abort_transaction: sym!(lib, "rd_kafka_abort_transaction"),
                error_name: sym!(lib, "rd_kafka_error_name"),
                error_is_fatal: sym!(lib, "rd_kafka_error_is_fatal"),
                error_is_retriable: sym!(lib, "rd_kafka_error_is_retriable"),
                error_txn_requires_abort: sym!(lib, "rd_kafka_error_txn_requires_abort"),
                _lib: lib,
            })
        }
    }

    pub fn err_name(&self, code: c_int) -> String {
        unsafe { CStr::from_ptr((self.err2name)(code)).to_string_lossy().into_owned() }
    }

    /// Read and free an `rd_kafka_error_t` (None for a null one: the call succeeded).
    pub fn take_error(&self, err: *mut c_void) -> Option<TxnError> {
        if err.is_null() {
            return None;
        }
        unsafe {
            let text = |p: *const c_char| CStr::from_ptr(p).to_string_lossy().into_owned();
            let out = TxnError {
                name: text((self.error_name)(err)),
                message: text((self.error_string)(err)),
                fatal: (self.error_is_fatal)(err) != 0,
                retriable: (self.error_is_retriable)(err) != 0,
                requires_abort: (self.error_txn_requires_abort)(err) != 0,
            };
            (self.error_destroy)(err);
            Some(out)
        }
    }

    pub fn err_str(&self, code: c_int) -> String {
        unsafe { CStr::from_ptr((self.err2str)(code)).to_string_lossy().into_owned() }
    }
}
