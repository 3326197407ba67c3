//! [`Memo`]: one value judged once and kept with the key it was judged for. The
//! [`Experiment`](crate::prepare::experiment::Experiment) keeps what several stages ask for
//! and each costs seconds to make (the view search, the joins, the clearance occupancy); the
//! key holds what the value reads besides what `prepare` fixed, so a config edited since gets
//! a fresh value instead of a stale one.

use std::sync::{Mutex, PoisonError};

/// The last value made and the key it was made for; a different key makes it again.
#[derive(Debug)]
pub struct Memo<K, V> {
    kept: Mutex<Option<(K, V)>>,
}

impl<K, V> Default for Memo<K, V> {
    fn default() -> Self {
        Self {
            kept: Mutex::new(None),
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
        *self.lock() = Some((key, value.clone()));
        Ok(value)
    }

    /// A copy of the value kept for `key`, if that is the key it was made for.
    fn kept_for(&self, key: &K) -> Option<V> {
        self.lock()
            .as_ref()
            .filter(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
    }

    /// The slot, even after a thread panicked holding it: a value is stored whole or not.
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<(K, V)>> {
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
}
