//! The thread pool the kernels run on: a dedicated, named rayon pool (never rayon's global one,
//! which belongs to the host application), sized by [`set_num_threads`], else by the
//! `DQSKIN_NUM_THREADS` environment variable, else by the number of available cores.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, RwLock};

use rayon::{ThreadPool, ThreadPoolBuilder};

mod placement;
use placement::Placement;

/// The pool's threads and where they may run.
struct Pool {
    threads: ThreadPool,
    placement: Arc<Placement>,
}

static POOL: RwLock<Option<Arc<Pool>>> = RwLock::new(None);

thread_local! {
    /// Inside [`alone`] on this thread: [`share`] runs every task here.
    static ALONE: Cell<bool> = const { Cell::new(false) };
}

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

fn build(threads: usize) -> Result<Pool, PoolError> {
    let placement = Arc::new(Placement::new());
    let (starts, exits) = (Arc::clone(&placement), Arc::clone(&placement));
    let threads = ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("dqskin-{i}"))
        .start_handler(move |_| starts.register())
        .exit_handler(move |_| exits.leave())
        .build()
        .map_err(|e| PoolError::Spawn(e.to_string()))?;
    Ok(Pool { threads, placement })
}

fn pool() -> Arc<Pool> {
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
    pool().threads.current_num_threads()
}

/// Runs `f` inside the pool (so rayon calls in `f` use it) and waits for it.
pub fn run<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    let pool = pool();
    pool.placement.free();
    pool.threads.install(f)
}

/// Runs `task(i)` for every `i` in `0..count` on the pool's threads with the calling thread
/// taking tasks too, each task once. From outside the pool the caller hands it at most one
/// helper per thread but one and works meanwhile, instead of handing all of it over and
/// sleeping until it is done: each hand-over wakes threads (on a virtual machine, tens of
/// microseconds), which inside Blender's evaluation cost as much as a Rigify character's
/// kernel gained from its second thread (see docs/performance.md). Meanwhile the helpers are
/// kept off the caller's CPU (`placement.rs`). Inside the pool (a batch's jobs, each on a
/// worker) it is rayon's parallel loop.
pub fn share(count: usize, task: impl Fn(usize) + Sync) {
    if count <= 1 || is_alone() {
        (0..count).for_each(task);
        return;
    }
    share_on(&pool(), count, task);
}

fn share_on(pool: &Pool, count: usize, task: impl Fn(usize) + Sync) {
    let threads = &pool.threads;
    if threads.current_thread_index().is_some() {
        use rayon::prelude::*;
        (0..count).into_par_iter().with_max_len(1).for_each(&task);
        return;
    }
    let helpers = threads.current_num_threads().min(count) - 1;
    if helpers > 0 {
        pool.placement.keep_off_caller();
    }
    // Guided: each claim takes a run of tasks in order, a share of what is left (at least one),
    // so that a large job's participants each stream long runs of memory, and the last claims
    // are small enough to balance. (Claiming one task at a time cost large meshes about 10 %:
    // 4M vertices on two threads, in one process against the pool's own loop.)
    let participants = helpers + 1;
    let next = AtomicUsize::new(0);
    let claim = || {
        let mut start = next.load(Ordering::Relaxed);
        loop {
            if start >= count {
                return None;
            }
            let run = ((count - start) / (2 * participants)).max(1);
            match next.compare_exchange_weak(start, start + run, Ordering::Relaxed, Ordering::Relaxed) {
                Ok(_) => return Some(start..start + run),
                Err(now) => start = now,
            }
        }
    };
    let drain = || {
        while let Some(run) = claim() {
            run.for_each(&task);
        }
    };
    threads.in_place_scope(|scope| {
        for _ in 0..helpers {
            scope.spawn(|_| drain());
        }
        drain();
    });
}

/// Runs `f` with every [`share`] it makes on the calling thread alone, no helper woken (the
/// pool's own loops, [`run`], still hand their work over). For a host that calls from inside
/// its own multithreaded work (Blender's evaluation, whose threads hold the other cores): there
/// a helper's wake-up costs more than it gains on small meshes (docs/performance.md).
pub fn alone<R>(f: impl FnOnce() -> R) -> R {
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            ALONE.set(self.0);
        }
    }
    let _restore = Restore(ALONE.replace(true));
    f()
}

/// Whether the calling thread is inside [`alone`].
pub fn is_alone() -> bool {
    ALONE.get()
}

/// [`share`] over `parts`: `task(i, part)` for each, each part to one task.
pub fn share_parts<T: Send>(parts: Vec<T>, task: impl Fn(usize, T) + Sync) {
    let parts: Vec<Mutex<Option<T>>> = parts.into_iter().map(|p| Mutex::new(Some(p))).collect();
    share(parts.len(), |i| {
        let part = parts[i].lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(part) = part {
            task(i, part);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU32;

    /// Every task runs exactly once, called from outside the pool and from one of its threads.
    #[test]
    fn share_runs_each_task_once() {
        for count in [0, 1, 2, 3, 100] {
            let check = |runs: Vec<AtomicU32>| assert!(runs.iter().all(|r| r.load(Ordering::Relaxed) == 1), "{count}");
            let runs: Vec<AtomicU32> = (0..count).map(|_| AtomicU32::new(0)).collect();
            share(count, |i| {
                runs[i].fetch_add(1, Ordering::Relaxed);
            });
            check(runs);
            let runs: Vec<AtomicU32> = (0..count).map(|_| AtomicU32::new(0)).collect();
            run(|| {
                share(count, |i| {
                    runs[i].fetch_add(1, Ordering::Relaxed);
                })
            });
            check(runs);
        }
        let mut parts = vec![0u8; 10];
        share_parts(parts.chunks_mut(3).collect(), |i, part| part.fill(i as u8 + 1));
        assert_eq!(parts, [1, 1, 1, 2, 2, 2, 3, 3, 3, 4]);
    }

    /// Inside `alone`, every task of a share runs on the calling thread, in order; after it (a
    /// panic too) the thread is no longer alone. (Not checked here: that a share outside it uses
    /// two threads, which another test's switch of the pool to one thread would make hang.)
    #[test]
    fn alone_runs_every_task_on_the_caller() {
        let caller = std::thread::current().id();
        let order = Mutex::new(Vec::new());
        alone(|| {
            share(50, |i| {
                assert_eq!(std::thread::current().id(), caller);
                order.lock().unwrap().push(i);
            })
        });
        assert_eq!(order.into_inner().unwrap(), (0..50).collect::<Vec<_>>());
        assert!(!is_alone());
        assert!(std::panic::catch_unwind(|| alone(|| panic!("inside"))).is_err());
        assert!(!is_alone());
    }

    /// While a caller outside the pool shares, the pool's threads are kept off one CPU (the
    /// caller's, where a helper would only take turns with it), and the pool's own loops give
    /// them back every CPU they started with. A pool of its own: other tests replace the global
    /// one.
    #[cfg(target_os = "linux")]
    #[test]
    fn helpers_are_kept_off_the_callers_cpu_while_it_shares() {
        let pool = build(2).unwrap();
        let started = std::time::Instant::now();
        while pool.placement.current().len() < 2 {
            assert!(started.elapsed().as_secs() < 10, "the pool's threads did not start");
            std::thread::yield_now();
        }
        let cpus = |set: &libc::cpu_set_t| unsafe { libc::CPU_COUNT(set) };
        if pool.placement.current().iter().any(|(own, _)| cpus(own) < 2) {
            return; // (one CPU: nowhere else to keep them)
        }
        let runs = AtomicU32::new(0);
        share_on(&pool, 64, |_| {
            runs.fetch_add(1, Ordering::Relaxed);
        });
        assert_eq!(runs.load(Ordering::Relaxed), 64);
        let kept_off = pool.placement.kept_off().expect("kept off a CPU");
        for (own, now) in pool.placement.current() {
            assert!(unsafe { libc::CPU_ISSET(kept_off, &own) });
            assert!(!unsafe { libc::CPU_ISSET(kept_off, &now) });
            assert_eq!(cpus(&now), cpus(&own) - 1);
        }
        pool.placement.free();
        assert_eq!(pool.placement.kept_off(), None);
        for (own, now) in pool.placement.current() {
            assert_eq!(cpus(&now), cpus(&own));
            assert!(unsafe { libc::CPU_ISSET(kept_off, &now) });
        }
    }

    /// A task that panics, on the caller or on a helper, panics the call (it does not abort the
    /// process or hang it).
    #[test]
    fn a_panicking_task_panics_the_call() {
        for bad in [0, 99] {
            let result = std::panic::catch_unwind(|| {
                share(100, |i| {
                    if i == bad {
                        panic!("task {i}");
                    }
                })
            });
            assert!(result.is_err(), "task {bad}");
        }
    }
}
