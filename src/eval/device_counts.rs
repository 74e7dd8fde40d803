//! What a GPU does for a piece of work, counted: kernel launches, host reads (device to
//! host: each one waits for the device to finish what was queued) and uploads (host to
//! device), from the `tracing` spans of burn's GPU backend (burn-cubecl's `float_into_data`
//! and `float_from_data`, cubecl's `launch_inner`). Behind the `wgpu` feature.
//!
//! A process-wide subscriber is installed on first use and counts for the whole process, so
//! a region is measured as the difference of two [`snapshot`]s taken on either side of it
//! (a test binary with one test, or a benchmark, is the place to do it). Counts on the CPU
//! (flex) are always zero: its tensors are host memory, and it has no spans.
//!
//! Reads of integer and boolean tensors (`int_into_data`, `bool_into_data`) carry no span
//! in burn 0.22 and are not counted.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};

use tracing::span::{Attributes, Id, Record};
use tracing::subscriber::Interest;
use tracing::{Event, Metadata, Subscriber};

/// What was counted since the process began, or between two snapshots.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DeviceCounts {
    pub launches: u64,
    pub reads: u64,
    pub uploads: u64,
    /// Launches by kernel name.
    pub kernels: BTreeMap<String, u64>,
}

impl DeviceCounts {
    /// Both counts together.
    pub fn plus(&self, other: &DeviceCounts) -> DeviceCounts {
        let mut kernels = self.kernels.clone();
        for (k, n) in &other.kernels {
            *kernels.entry(k.clone()).or_default() += n;
        }
        DeviceCounts {
            launches: self.launches + other.launches,
            reads: self.reads + other.reads,
            uploads: self.uploads + other.uploads,
            kernels,
        }
    }

    /// What happened between `earlier` and `self`.
    pub fn since(&self, earlier: &DeviceCounts) -> DeviceCounts {
        DeviceCounts {
            launches: self.launches - earlier.launches,
            reads: self.reads - earlier.reads,
            uploads: self.uploads - earlier.uploads,
            kernels: self
                .kernels
                .iter()
                .map(|(k, &n)| (k.clone(), n - earlier.kernels.get(k).copied().unwrap_or(0)))
                .filter(|(_, n)| *n > 0)
                .collect(),
        }
    }
}

const LAUNCH: &str = "launch_inner";
const READ: &str = "float_into_data";
const UPLOAD: &str = "float_from_data";

struct Counter {
    launches: AtomicU64,
    reads: AtomicU64,
    uploads: AtomicU64,
    kernels: Mutex<BTreeMap<String, u64>>,
    next_id: AtomicU64,
}

/// Reads the `kernel.name` field of a launch span.
struct KernelName(Option<String>);

impl tracing::field::Visit for KernelName {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "kernel.name" {
            self.0 = Some(format!("{value:?}"));
        }
    }
    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "kernel.name" {
            self.0 = Some(value.to_string());
        }
    }
}

/// A kernel's name without its module path and type parameters:
/// `cubek_reduce::launch::base::reduce_kernel::ReduceKernel<..>` -> `ReduceKernel`, and
/// `..::KernelBinop<..::MulOp>` -> `KernelBinop<MulOp>` (one parameter that names an
/// operation is kept).
pub fn short_name(full: &str) -> String {
    let last = |path: &str| path.rsplit("::").next().unwrap_or(path).to_string();
    match full.split_once('<') {
        None => last(full),
        Some((head, params)) => {
            let params = params.trim_end_matches('>');
            if params.contains(',') || params.contains('<') {
                last(head)
            } else {
                format!("{}<{}>", last(head), last(params))
            }
        }
    }
}

fn counted(metadata: &Metadata<'_>) -> bool {
    metadata.is_span() && matches!(metadata.name(), LAUNCH | READ | UPLOAD)
}

/// The dispatcher owns a `'static` reference, so [`snapshot`] can read the same counter.
impl Subscriber for &'static Counter {
    fn register_callsite(&self, metadata: &'static Metadata<'static>) -> Interest {
        if counted(metadata) {
            Interest::always()
        } else {
            Interest::never()
        }
    }
    fn enabled(&self, metadata: &Metadata<'_>) -> bool {
        counted(metadata)
    }
    fn new_span(&self, span: &Attributes<'_>) -> Id {
        match span.metadata().name() {
            LAUNCH => {
                self.launches.fetch_add(1, Ordering::Relaxed);
                let mut name = KernelName(None);
                span.record(&mut name);
                let name = short_name(name.0.as_deref().unwrap_or("?"));
                *self
                    .kernels
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .entry(name)
                    .or_default() += 1;
            }
            READ => {
                // A read asks the backend below it to read (burn's fusion layer reads through
                // the cubecl backend, two spans for one read): only the outermost counts.
                if READ_DEPTH.with(|d| d.get()) == 0 {
                    self.reads.fetch_add(1, Ordering::Relaxed);
                }
                let id = (self.next_id.fetch_add(1, Ordering::Relaxed) + 1) * 2 + 1;
                return Id::from_u64(id);
            }
            UPLOAD => {
                self.uploads.fetch_add(1, Ordering::Relaxed);
            }
            _ => {}
        }
        Id::from_u64((self.next_id.fetch_add(1, Ordering::Relaxed) + 1) * 2)
    }
    fn record(&self, _: &Id, _: &Record<'_>) {}
    fn record_follows_from(&self, _: &Id, _: &Id) {}
    fn event(&self, _: &Event<'_>) {}
    fn enter(&self, span: &Id) {
        if span.into_u64() % 2 == 1 {
            READ_DEPTH.with(|d| d.set(d.get() + 1));
        }
    }
    fn exit(&self, span: &Id) {
        if span.into_u64() % 2 == 1 {
            READ_DEPTH.with(|d| d.set(d.get().saturating_sub(1)));
        }
    }
}

thread_local! {
    /// Read spans entered on this thread and not yet left (odd span ids are reads).
    static READ_DEPTH: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

static COUNTER: OnceLock<&'static Counter> = OnceLock::new();

/// Start counting (the first call installs the process's subscriber; `false` when another
/// subscriber was installed first and nothing can be counted).
pub fn install() -> bool {
    let mut installed = true;
    COUNTER.get_or_init(|| {
        let counter: &'static Counter = Box::leak(Box::new(Counter {
            launches: AtomicU64::new(0),
            reads: AtomicU64::new(0),
            uploads: AtomicU64::new(0),
            kernels: Mutex::new(BTreeMap::new()),
            next_id: AtomicU64::new(0),
        }));
        installed = tracing::subscriber::set_global_default(counter).is_ok();
        counter
    });
    installed
}

/// The counts so far (zero before [`install`]).
pub fn snapshot() -> DeviceCounts {
    match COUNTER.get() {
        Some(c) => DeviceCounts {
            launches: c.launches.load(Ordering::Relaxed),
            reads: c.reads.load(Ordering::Relaxed),
            uploads: c.uploads.load(Ordering::Relaxed),
            kernels: c.kernels.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        },
        None => DeviceCounts::default(),
    }
}
