//! What a memory reader keeps per data-block between reads (by address), bounded.

use std::collections::HashMap;
use std::sync::{Mutex, MutexGuard};

/// Values kept by address, at most `most` of them: when full, a new address forgets them all
/// (addresses of removed data-blocks are not told apart from live ones).
pub struct KeptByAddress<T> {
    map: Mutex<HashMap<usize, T>>,
    most: usize,
}

impl<T> KeptByAddress<T> {
    pub fn new(most: usize) -> Self {
        Self { map: Mutex::default(), most }
    }

    /// `f` of the value kept for `at` (None: none), under the lock.
    pub fn with<R>(&self, at: usize, f: impl FnOnce(Option<&mut T>) -> R) -> R {
        f(self.lock().get_mut(&at))
    }

    /// `value` kept for `at`, in place of what was.
    pub fn put(&self, at: usize, value: T) {
        let mut map = self.lock();
        if map.len() >= self.most && !map.contains_key(&at) {
            map.clear();
        }
        map.insert(at, value);
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<usize, T>> {
        self.map.lock().unwrap_or_else(|e| e.into_inner())
    }
}
