//! The thread pool the kernels run on: a dedicated, named rayon pool (never rayon's global one,
//! which belongs to the host application), sized by [`set_num_threads`], else by the
//! `DQSKIN_NUM_THREADS` environment variable, else by the number of available cores.

use std::sync::{Arc, RwLock};

use rayon::{ThreadPool, ThreadPoolBuilder};

static POOL: RwLock<Option<Arc<ThreadPool>>> = RwLock::new(None);

/// Why the thread count could not be set.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PoolError {
    /// Zero threads were asked for.
    ZeroThreads,
    /// More threads than [`max_threads`].
    TooMany { asked: usize, max: usize },
    /// The operating system refused to start the threads.
    Spawn(String),
}

impl core::fmt::Display for PoolError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PoolError::ZeroThreads => write!(f, "the number of threads must be at least 1"),
            PoolError::TooMany { asked, max } => write!(
                f,
                "{asked} threads is more than this machine can use: at most {max} (4 per core, at least 16, at most 1024)"
            ),
            PoolError::Spawn(e) => write!(f, "could not start the worker threads: {e}"),
        }
    }
}

impl std::error::Error for PoolError {}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The most threads [`set_num_threads`] accepts: 4 per core, at least 16, at most 1024. More
/// only compete for the same cores, and asking the operating system for thousands can fail
/// halfway.
pub fn max_threads() -> usize {
    (4 * cores()).clamp(16, 1024)
}

fn default_threads() -> usize {
    std::env::var("DQSKIN_NUM_THREADS")
        .ok()
        .and_then(|s| s.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .map(|n| n.min(max_threads()))
        .unwrap_or_else(cores)
}

fn build(threads: usize) -> Result<ThreadPool, PoolError> {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("dqskin-{i}"))
        .build()
        .map_err(|e| PoolError::Spawn(e.to_string()))
}

fn pool() -> Arc<ThreadPool> {
    if let Some(p) = POOL.read().unwrap_or_else(|e| e.into_inner()).as_ref() {
        return Arc::clone(p);
    }
    let mut slot = POOL.write().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = slot.as_ref() {
        return Arc::clone(p);
    }
    // Falling back to one thread keeps skinning working if the OS will not give us more.
    let p = Arc::new(build(default_threads()).or_else(|_| build(1)).expect("a one-thread pool"));
    *slot = Some(Arc::clone(&p));
    p
}

/// Sets the number of worker threads (replacing the pool; calls already running finish on the
/// old one).
pub fn set_num_threads(threads: usize) -> Result<(), PoolError> {
    if threads == 0 {
        return Err(PoolError::ZeroThreads);
    }
    if threads > max_threads() {
        return Err(PoolError::TooMany { asked: threads, max: max_threads() });
    }
    let p = Arc::new(build(threads)?);
    *POOL.write().unwrap_or_else(|e| e.into_inner()) = Some(p);
    Ok(())
}

/// The number of worker threads kernels use.
pub fn num_threads() -> usize {
    pool().current_num_threads()
}

/// Runs `f` inside the pool (so rayon calls in `f` use it) and waits for it.
pub fn run<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    pool().install(f)
}
