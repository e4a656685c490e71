//! Where the pool's threads may run while a caller from outside the pool shares its work with
//! them ([`super::share`]).
//!
//! A helper woken by a thread of a host's own multithreaded work (Blender's evaluation, whose
//! waiting threads keep the other CPUs busy) is placed by Linux on the caller's own CPU, where it
//! only takes turns with the caller: inside Blender a 250k-vertex job took as long on two threads
//! as on one (docs/performance.md). So while a caller shares, the pool's threads are kept off its
//! CPU, and before the pool's own loops ([`super::run`], whose caller waits) they get their CPUs
//! back. The masks change only when the caller's CPU does. Only the pool's own threads are ever
//! touched, and only while they run (each registers as it starts and leaves as it exits).
//! Elsewhere than Linux nothing changes.

#[cfg(target_os = "linux")]
pub(super) use linux::Placement;

#[cfg(not(target_os = "linux"))]
pub(super) use other::Placement;

#[cfg(target_os = "linux")]
mod linux {
    use std::mem::size_of;
    use std::sync::atomic::{AtomicI32, Ordering};
    use std::sync::{Mutex, MutexGuard};

    /// `kept_off` when the threads have their own CPUs.
    const FREE: i32 = -1;

    /// One pool thread: its id and the CPUs it started with.
    struct Thread {
        tid: libc::pid_t,
        own: libc::cpu_set_t,
    }

    pub(in crate::pool) struct Placement {
        threads: Mutex<Vec<Thread>>,
        /// The CPU the threads are kept off, or [`FREE`].
        kept_off: AtomicI32,
    }

    fn this_thread() -> libc::pid_t {
        // SAFETY: gettid takes no arguments and cannot fail. (The syscall, not glibc's wrapper,
        // which the oldest glibc the module is linked against lacks.)
        unsafe { libc::syscall(libc::SYS_gettid) as libc::pid_t }
    }

    fn set_affinity(tid: libc::pid_t, set: &libc::cpu_set_t) {
        // SAFETY: `set` is a valid cpu_set_t of the size given. A refusal (a CPU the process
        // may no longer use) leaves the thread where it was: placement is only a hint.
        unsafe {
            libc::sched_setaffinity(tid, size_of::<libc::cpu_set_t>(), set);
        }
    }

    impl Placement {
        pub(in crate::pool) fn new() -> Self {
            Placement { threads: Mutex::new(Vec::new()), kept_off: AtomicI32::new(FREE) }
        }

        fn threads(&self) -> MutexGuard<'_, Vec<Thread>> {
            self.threads.lock().unwrap_or_else(|e| e.into_inner())
        }

        /// Called on each pool thread as it starts.
        pub(in crate::pool) fn register(&self) {
            // SAFETY: an all-zero cpu_set_t is an empty set; sched_getaffinity fills it.
            let mut own: libc::cpu_set_t = unsafe { std::mem::zeroed() };
            // SAFETY: `own` is a valid cpu_set_t of the size given; 0 is the calling thread.
            if unsafe { libc::sched_getaffinity(0, size_of::<libc::cpu_set_t>(), &mut own) } != 0 {
                return;
            }
            let mut threads = self.threads();
            let tid = this_thread();
            let kept_off = self.kept_off.load(Ordering::Relaxed);
            if kept_off != FREE {
                set_affinity(tid, &without(&own, kept_off));
            }
            threads.push(Thread { tid, own });
        }

        /// Called on each pool thread as it exits: its id may then be given to another thread.
        pub(in crate::pool) fn leave(&self) {
            let tid = this_thread();
            self.threads().retain(|t| t.tid != tid);
        }

        /// Keeps the pool's threads off the calling thread's CPU (where they would only take
        /// turns with it); a thread whose only CPU it is stays where it is.
        pub(in crate::pool) fn keep_off_caller(&self) {
            // SAFETY: sched_getcpu takes no arguments; it returns -1 where it is not known.
            let cpu = unsafe { libc::sched_getcpu() };
            if cpu < 0 || cpu as usize >= libc::CPU_SETSIZE as usize || self.kept_off.load(Ordering::Relaxed) == cpu {
                return;
            }
            let threads = self.threads();
            for t in threads.iter() {
                set_affinity(t.tid, &without(&t.own, cpu));
            }
            self.kept_off.store(cpu, Ordering::Relaxed);
        }

        /// Gives the pool's threads the CPUs they started with.
        pub(in crate::pool) fn free(&self) {
            if self.kept_off.load(Ordering::Relaxed) == FREE {
                return;
            }
            let threads = self.threads();
            for t in threads.iter() {
                set_affinity(t.tid, &t.own);
            }
            self.kept_off.store(FREE, Ordering::Relaxed);
        }

        /// The CPU the threads are kept off (tests).
        #[cfg(test)]
        pub(in crate::pool) fn kept_off(&self) -> Option<usize> {
            let cpu = self.kept_off.load(Ordering::Relaxed);
            (cpu != FREE).then_some(cpu as usize)
        }

        /// Each registered thread's CPUs: those it started with and those it has now (tests).
        #[cfg(test)]
        pub(in crate::pool) fn current(&self) -> Vec<(libc::cpu_set_t, libc::cpu_set_t)> {
            self.threads()
                .iter()
                .map(|t| {
                    // SAFETY: as in `register`, for the thread `t.tid`.
                    let mut now: libc::cpu_set_t = unsafe { std::mem::zeroed() };
                    unsafe { libc::sched_getaffinity(t.tid, size_of::<libc::cpu_set_t>(), &mut now) };
                    (t.own, now)
                })
                .collect()
        }
    }

    /// `own` without `cpu`, or `own` itself where `cpu` is its only CPU.
    fn without(own: &libc::cpu_set_t, cpu: i32) -> libc::cpu_set_t {
        let mut set = *own;
        // SAFETY: `cpu` is below CPU_SETSIZE: `keep_off_caller` checks it before keeping a CPU.
        unsafe { libc::CPU_CLR(cpu as usize, &mut set) };
        // SAFETY: `set` is a valid cpu_set_t.
        if unsafe { libc::CPU_COUNT(&set) } == 0 {
            return *own;
        }
        set
    }
}

#[cfg(not(target_os = "linux"))]
mod other {
    pub(in crate::pool) struct Placement;

    impl Placement {
        pub(in crate::pool) fn new() -> Self {
            Placement
        }
        pub(in crate::pool) fn register(&self) {}
        pub(in crate::pool) fn leave(&self) {}
        pub(in crate::pool) fn keep_off_caller(&self) {}
        pub(in crate::pool) fn free(&self) {}
    }
}
