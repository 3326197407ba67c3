//! [`Memo`]: values judged once and kept with the key each was judged for. The
//! [`Experiment`](crate::prepare::experiment::Experiment) keeps what several stages ask for
//! and each costs seconds to make (the view search, the joins, the clearance occupancy, the
//! scene on the device); the key holds what the value reads besides what `prepare` fixed, so
//! a config edited since gets a fresh value instead of a stale one.

use std::collections::VecDeque;
use std::sync::{Mutex, PoisonError};

/// The last values made (at most `capacity`) and the keys they were made for; another key
/// makes its value again, and the oldest kept goes.
#[derive(Debug)]
pub struct Memo<K, V> {
    kept: Mutex<VecDeque<(K, V)>>,
    capacity: usize,
}

impl<K, V> Default for Memo<K, V> {
    /// Keeps one value.
    fn default() -> Self {
        Self::keeping(1)
    }
}

impl<K, V> Memo<K, V> {
    /// A memo that keeps the last `capacity` values (at least one).
    pub fn keeping(capacity: usize) -> Self {
        Self {
            kept: Mutex::new(VecDeque::new()),
            capacity: capacity.max(1),
        }
    }
}

impl<K: PartialEq, V: Clone> Memo<K, V> {
    /// The value kept for `key`, else `make()`'s (kept in its place when it succeeds).
    pub fn get_or_make<E>(&self, key: K, make: impl FnOnce() -> Result<V, E>) -> Result<V, E> {
        if let Some(value) = self.kept_for(&key) {
            return Ok(value);
        }
        // Made without the lock held: making one value may ask another memo (or, in another
        // thread, this one) without waiting on it.
        let value = make()?;
        let mut kept = self.lock();
        kept.retain(|(k, _)| *k != key);
        kept.push_back((key, value.clone()));
        while kept.len() > self.capacity {
            kept.pop_front();
        }
        Ok(value)
    }

    /// [`Memo::get_or_make`] of a `make` that cannot fail.
    pub fn get_or_insert(&self, key: K, make: impl FnOnce() -> V) -> V {
        match self.get_or_make(key, || Ok::<_, std::convert::Infallible>(make())) {
            Ok(value) => value,
            Err(never) => match never {},
        }
    }

    /// A copy of the value kept for `key`, if one was made for it.
    fn kept_for(&self, key: &K) -> Option<V> {
        self.lock()
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
    }

    /// The slot, even after a thread panicked holding it: a value is stored whole or not.
    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<(K, V)>> {
        self.kept.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

#[cfg(test)]
mod tests {
    use super::Memo;

    #[test]
    fn a_value_is_made_once_per_key_and_again_for_a_new_key() {
        let memo = Memo::<u32, String>::default();
        let made = std::cell::Cell::new(0);
        let get = |key: u32| {
            memo.get_or_make(key, || {
                made.set(made.get() + 1);
                Ok::<_, ()>(format!("value {key}"))
            })
            .unwrap()
        };
        assert_eq!(get(1), "value 1");
        assert_eq!(get(1), "value 1");
        assert_eq!(get(2), "value 2");
        assert_eq!(get(2), "value 2");
        assert_eq!(made.get(), 2);
        // A failure keeps nothing.
        assert_eq!(memo.get_or_make(3, || Err("no")), Err("no"));
        assert_eq!(memo.get_or_make(2, || Err("no")), Ok("value 2".to_string()));
    }

    #[test]
    fn a_memo_keeps_its_last_values_up_to_its_capacity() {
        let memo = Memo::<u32, u32>::keeping(2);
        let made = std::cell::Cell::new(0);
        let get = |key: u32| {
            memo.get_or_make(key, || {
                made.set(made.get() + 1);
                Ok::<_, ()>(10 * key)
            })
            .unwrap()
        };
        assert_eq!((get(1), get(2), get(1), get(2)), (10, 20, 10, 20));
        assert_eq!(made.get(), 2);
        // A third key: the oldest (1) goes, 2 stays.
        assert_eq!((get(3), get(2)), (30, 20));
        assert_eq!(made.get(), 3);
        assert_eq!(get(1), 10);
        assert_eq!(made.get(), 4);
    }
}
