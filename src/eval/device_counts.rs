//! What a GPU does for a piece of work, counted: kernel launches, host reads (device to
//! host: each one waits for the device to finish what was queued) and uploads (host to
//! device), each launch's workgroups and, for our kernels, the elements it works over, from
//! the `tracing` spans of burn's GPU backend (burn-cubecl's `float_into_data` and
//! `float_from_data`, cubecl's `launch_inner`). Behind the `cube` feature (`wgpu`, `cuda`).
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
    /// Launches by kernel name and the operations burn's fusion backend ran them for
    /// (`kernel <- operation+operation`): which operation asks for each copy, reduction or
    /// fill. Launches outside fusion's blocks (none in a training step) are `kernel <- ?`.
    pub sources: BTreeMap<String, u64>,
}

impl DeviceCounts {
    /// Both counts together.
    pub fn plus(&self, other: &DeviceCounts) -> DeviceCounts {
        let add = |a: &BTreeMap<String, u64>, b: &BTreeMap<String, u64>| {
            let mut sum = a.clone();
            for (k, n) in b {
                *sum.entry(k.clone()).or_default() += n;
            }
            sum
        };
        DeviceCounts {
            launches: self.launches + other.launches,
            reads: self.reads + other.reads,
            uploads: self.uploads + other.uploads,
            kernels: add(&self.kernels, &other.kernels),
            sources: add(&self.sources, &other.sources),
        }
    }

    /// What happened between `earlier` and `self`.
    pub fn since(&self, earlier: &DeviceCounts) -> DeviceCounts {
        let less = |a: &BTreeMap<String, u64>, b: &BTreeMap<String, u64>| {
            a.iter()
                .map(|(k, &n)| (k.clone(), n - b.get(k).copied().unwrap_or(0)))
                .filter(|(_, n)| *n > 0)
                .collect()
        };
        DeviceCounts {
            launches: self.launches - earlier.launches,
            reads: self.reads - earlier.reads,
            uploads: self.uploads - earlier.uploads,
            kernels: less(&self.kernels, &earlier.kernels),
            sources: less(&self.sources, &earlier.sources),
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
    sources: Mutex<BTreeMap<String, u64>>,
    next_id: AtomicU64,
}

/// Reads the `kernel.name` and `count` (the workgroups, `(x, y, z)`) fields of a launch span.
#[derive(Default)]
struct LaunchFields {
    name: Option<String>,
    count: Option<String>,
}

impl tracing::field::Visit for LaunchFields {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        match field.name() {
            "kernel.name" => self.name = Some(format!("{value:?}")),
            "count" => self.count = Some(format!("{value:?}")),
            _ => {}
        }
    }
    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "kernel.name" {
            self.name = Some(value.to_string());
        }
    }
}

/// The workgroups of a launch from its `count` field (cubecl's `CubeCount` as `Debug` prints
/// it): `(x, y, z)` -> `x·y·z`; `None` for a count read from a buffer (`binding`).
pub fn workgroups(count: &str) -> Option<u64> {
    let inside = count.trim().strip_prefix('(')?.strip_suffix(')')?;
    inside
        .split(',')
        .map(|d| d.trim().parse::<u64>().ok())
        .product()
}

/// One kernel launch, as [`launch_log`] keeps it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Launch {
    /// The kernel's short name ([`short_name`]).
    pub kernel: String,
    /// The operations of burn's fusion block it ran for (`?` outside one).
    pub operations: String,
    /// Its workgroups (`None`: counted on the device).
    pub workgroups: Option<u64>,
    /// The elements it works over, where the launcher says (ours:
    /// `kernels::cube::over_elements`); `None` for burn's kernels.
    pub elements: Option<u64>,
    /// The fusion block it ran for (numbered in order since the process began); `None` outside
    /// one.
    pub block: Option<u64>,
    /// What that whole block moves and computes ([`block_work`]): shared by its launches.
    pub work: Work,
}

/// The bytes a block of operations moves to and from memory and the floating-point operations
/// its matrix products compute, estimated from burn's IR: every tensor it reads that it did
/// not produce, and every tensor it produces that outlives it (not consumed inside it for the
/// last time); a product of `[.., m, k]` by `[.., k, n]` is `2·m·n·k` a batch. Elementwise
/// arithmetic is not counted (it is bound by the bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Work {
    pub bytes: u64,
    pub flops: u64,
}

/// [`Work`] of the operations of one block, in the order they run.
pub fn block_work<'a>(
    operations: impl Iterator<Item = &'a burn::backend::ir::OperationIr>,
) -> Work {
    use burn::backend::ir::{FloatOperationIr, OperationIr, TensorStatus};
    use std::collections::{HashMap, HashSet};
    let size = |t: &burn::backend::ir::TensorIr| (t.shape.num_elements() * t.dtype.size()) as u64;
    let mut read = HashSet::new();
    // Produced here: whether it is still needed after the block.
    let mut produced: HashMap<_, (u64, bool)> = HashMap::new();
    let mut work = Work::default();
    for op in operations {
        if matches!(op, OperationIr::Drop(_)) {
            continue;
        }
        for t in op.inputs() {
            match produced.get_mut(&t.id) {
                // Consumed for the last time here: it never reaches memory.
                Some(p) => p.1 = t.status != TensorStatus::ReadWrite,
                None => {
                    if read.insert(t.id) {
                        work.bytes += size(t);
                    }
                }
            }
        }
        for t in op.outputs() {
            produced.insert(t.id, (size(t), true));
        }
        if let OperationIr::Float(_, FloatOperationIr::Matmul(m)) = op {
            let k = m.lhs.shape.last().copied().unwrap_or(0);
            work.flops += 2 * m.out.shape.num_elements() as u64 * k as u64;
        }
    }
    work.bytes += produced.values().filter(|p| p.1).map(|p| p.0).sum::<u64>();
    work
}

impl std::fmt::Display for Launch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let or_q = |v: Option<u64>| v.map_or("?".to_string(), |v| v.to_string());
        write!(
            f,
            "{} <- {} ({} workgroups, {} elements)",
            self.kernel,
            self.operations,
            or_q(self.workgroups),
            or_q(self.elements)
        )
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
                let mut fields = LaunchFields::default();
                span.record(&mut fields);
                let name = short_name(fields.name.as_deref().unwrap_or("?"));
                let block = BLOCK.with(|b| b.borrow().clone());
                let operations = block
                    .as_ref()
                    .map_or_else(|| "?".to_string(), |b| b.names.clone());
                let source = format!("{name} <- {operations}");
                if let Some(log) = LOG.get() {
                    let mut log = log.lock().unwrap_or_else(|e| e.into_inner());
                    if log.len() < 100_000 {
                        log.push(Launch {
                            kernel: name.clone(),
                            operations,
                            workgroups: fields.count.as_deref().and_then(workgroups),
                            elements: crate::kernels::cube::launch_elements(),
                            block: block.as_ref().map(|b| b.id),
                            work: block.map(|b| b.work).unwrap_or_default(),
                        });
                    }
                }
                *self
                    .sources
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .entry(source)
                    .or_default() += 1;
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
    /// The operations of the fusion block running on this thread (the fusion server's).
    static BLOCK: std::cell::RefCell<Option<Block>> = const { std::cell::RefCell::new(None) };
}

/// An operation of burn's IR by its kind: `BaseFloat(SwapDims(..))` -> `SwapDims`,
/// `NumericFloat(F32, Add(..))` -> `Add`, `Custom(CustomOpIr { id: "adam", .. })` -> `adam`.
pub fn operation_name(debug: &str) -> String {
    if let Some(rest) = debug.strip_prefix("Custom(")
        && let Some(start) = rest.find("id: \"")
    {
        let id = &rest[start + 5..];
        return id.split('"').next().unwrap_or("custom").to_string();
    }
    let words: Vec<&str> = debug
        .split(|c: char| !c.is_alphanumeric() && c != '_')
        .filter(|w| !w.is_empty())
        .take(4)
        .collect();
    let is_dtype = |w: &str| {
        matches!(
            w,
            "F64"
                | "F32"
                | "F16"
                | "BF16"
                | "Flex32"
                | "I64"
                | "I32"
                | "I16"
                | "I8"
                | "U64"
                | "U32"
                | "U16"
                | "U8"
                | "Bool"
        )
    };
    words
        .iter()
        .skip(1)
        .find(|w| !is_dtype(w) && w.chars().next().is_some_and(char::is_uppercase))
        .or(words.first())
        .map(|w| w.to_string())
        .unwrap_or_default()
}

/// The fusion block running on a thread: its operations' kinds, its number and its work.
#[derive(Clone)]
struct Block {
    names: String,
    id: u64,
    work: Work,
}

/// Blocks started since the process began.
static BLOCKS: AtomicU64 = AtomicU64::new(0);

/// Names the operations of each fusion block on the server's thread while it runs.
struct BlockNames;

impl burn::backend::fusion::observer::FusionObserver for BlockNames {
    fn registered(&self, _operation: &burn::backend::ir::OperationIr) {}
    fn block_starts(&self, block: burn::backend::fusion::observer::BlockOperations<'_>) {
        let mut names: Vec<String> = Vec::new();
        for op in block.iter() {
            let name = operation_name(&format!("{op:?}"));
            if !names.contains(&name) {
                names.push(name);
            }
        }
        let summary = if names.len() > 6 {
            format!("{}+..({} kinds)", names[..6].join("+"), names.len())
        } else {
            names.join("+")
        };
        let running = Block {
            names: summary,
            id: BLOCKS.fetch_add(1, Ordering::Relaxed),
            work: block_work(block.iter()),
        };
        BLOCK.with(|b| *b.borrow_mut() = Some(running));
    }
    fn block_ran(&self) {
        BLOCK.with(|b| *b.borrow_mut() = None);
    }
}

static COUNTER: OnceLock<&'static Counter> = OnceLock::new();

/// Every launch in order, once [`log_launches`] was called.
static LOG: OnceLock<Mutex<Vec<Launch>>> = OnceLock::new();

/// Keep every launch from now on, in order, for [`launch_log`] (bounded: 100,000 launches).
pub fn log_launches() {
    LOG.get_or_init(|| Mutex::new(Vec::new()));
}

/// The launches kept since [`log_launches`], in order.
pub fn launch_log() -> Vec<Launch> {
    LOG.get()
        .map(|l| l.lock().unwrap_or_else(|e| e.into_inner()).clone())
        .unwrap_or_default()
}

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
            sources: Mutex::new(BTreeMap::new()),
            next_id: AtomicU64::new(0),
        }));
        installed = tracing::subscriber::set_global_default(counter).is_ok();
        // Kept for the process's life, as the subscriber.
        std::mem::forget(burn::backend::fusion::observer::FusionObservation::new(
            std::sync::Arc::new(BlockNames),
        ));
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
            sources: c.sources.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        },
        None => DeviceCounts::default(),
    }
}
