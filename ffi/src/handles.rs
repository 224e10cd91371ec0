//! The pointers C holds are handles, not addresses: a table maps each to its object.
//!
//! A `huddle_node *` or `huddle_replica *` is a number huddle handed out (never reused,
//! never dereferenced). Every call looks it up first, so a pointer that was stopped,
//! freed, or never came from huddle gives `HUDDLE_E_STOPPED` instead of a crash, and a
//! call racing a stop on another thread still holds its own reference to the object.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// Shared by every table, so that a node's handle is never also a replica's.
static NEXT_HANDLE: AtomicUsize = AtomicUsize::new(1);

/// Live objects of one kind by handle.
pub(crate) struct Handles<T> {
    table: Mutex<BTreeMap<usize, Arc<T>>>,
}

impl<T> Handles<T> {
    pub(crate) const fn new() -> Handles<T> {
        Handles {
            table: Mutex::new(BTreeMap::new()),
        }
    }

    fn table(&self) -> MutexGuard<'_, BTreeMap<usize, Arc<T>>> {
        // The table is never left half-updated: a poisoned lock is still consistent.
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Registers `object`; returns its handle as the pointer C holds.
    pub(crate) fn insert<P>(&self, object: Arc<T>) -> *mut P {
        // Multiples of 16, from 16: aligned-looking and never NULL.
        let handle = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed) << 4;
        self.table().insert(handle, object);
        std::ptr::without_provenance_mut(handle)
    }

    /// The object behind `ptr`, if it is live.
    pub(crate) fn get<P>(&self, ptr: *const P) -> Option<Arc<T>> {
        self.table().get(&ptr.addr()).cloned()
    }

    /// Unregisters `ptr`'s object and returns it.
    pub(crate) fn remove<P>(&self, ptr: *const P) -> Option<Arc<T>> {
        self.table().remove(&ptr.addr())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handles_are_never_reused_and_unknown_ones_are_none() {
        let table = Handles::<u32>::new();
        let a: *mut u8 = table.insert(Arc::new(1));
        assert_eq!(table.remove(a).as_deref(), Some(&1));
        let b: *mut u8 = table.insert(Arc::new(2));
        assert_ne!(a, b);
        assert!(table.get(a).is_none(), "a removed handle stays dead");
        assert!(table.get(std::ptr::null::<u8>()).is_none());
        assert_eq!(table.get(b).as_deref(), Some(&2));
    }
}
