//! The GPU-resident steps: kept under a byte budget, the least recently used evicted first,
//! the displayed step never.

use std::collections::HashMap;

/// Something the pool holds, with the bytes it occupies (on the GPU: sections and derived
/// buffers alike).
pub trait Resident {
    fn bytes(&self) -> u64;
}

impl Resident for slosh_render::GpuStep {
    fn bytes(&self) -> u64 {
        self.gpu_bytes()
    }
}

#[derive(Debug)]
struct Entry<T> {
    item: T,
    bytes: u64,
    last_used: u64,
}

/// What became of an insertion.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Admission {
    /// Stored; these steps were evicted to make room, least recently used first.
    Stored { evicted: Vec<usize> },
    /// Not stored: it would not fit even with every evictable step gone.
    Refused,
}

/// Steps by index under a byte budget.
#[derive(Debug)]
pub struct StepPool<T> {
    budget: u64,
    used: u64,
    clock: u64,
    entries: HashMap<usize, Entry<T>>,
}

impl<T: Resident> StepPool<T> {
    pub fn new(budget: u64) -> StepPool<T> {
        StepPool {
            budget,
            used: 0,
            clock: 0,
            entries: HashMap::new(),
        }
    }

    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Bytes held by the resident steps, as their own `bytes` report them.
    pub fn used(&self) -> u64 {
        self.used
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn contains(&self, index: usize) -> bool {
        self.entries.contains_key(&index)
    }

    /// The resident steps' indices, in no order.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.entries.keys().copied()
    }

    /// The step, marked as used now.
    pub fn get(&mut self, index: usize) -> Option<&T> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(&index).map(|e| {
            e.last_used = clock;
            &e.item
        })
    }

    /// The step, mutably (a field switched), marked as used now.
    pub fn get_mut(&mut self, index: usize) -> Option<&mut T> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(&index).map(|e| {
            e.last_used = clock;
            &mut e.item
        })
    }

    /// Re-reads a step's size after it changed (a field switched).
    pub fn refresh_bytes(&mut self, index: usize) {
        if let Some(e) = self.entries.get_mut(&index) {
            let bytes = e.item.bytes();
            self.used = self.used - e.bytes + bytes;
            e.bytes = bytes;
        }
    }

    /// The step without marking it used.
    pub fn peek(&self, index: usize) -> Option<&T> {
        self.entries.get(&index).map(|e| &e.item)
    }

    /// The resident step nearest to `index` (ties to the earlier step), without marking it.
    pub fn nearest(&self, index: usize) -> Option<usize> {
        self.nearest_by(|i| i.abs_diff(index))
    }

    /// The resident step of least `distance` (ties to the lower index), without marking it.
    pub fn nearest_by(&self, distance: impl Fn(usize) -> usize) -> Option<usize> {
        self.entries
            .keys()
            .copied()
            .min_by_key(|&i| (distance(i), i))
    }

    /// Whether a step of `bytes` fits with every step but `keep` evictable.
    pub fn could_hold(&self, bytes: u64, keep: Option<usize>) -> bool {
        let kept = keep
            .and_then(|k| self.entries.get(&k))
            .map_or(0, |e| e.bytes);
        kept + bytes <= self.budget
    }

    /// Stores `item` as step `index`, evicting least recently used steps other than `keep`
    /// (the displayed step) until it fits; refused where it cannot fit. A step stored again
    /// replaces the old one.
    pub fn insert(&mut self, index: usize, item: T, keep: Option<usize>) -> Admission {
        let bytes = item.bytes();
        if let Some(old) = self.entries.remove(&index) {
            self.used -= old.bytes;
        }
        let keep = keep.filter(|&k| k != index);
        if !self.could_hold(bytes, keep) {
            return Admission::Refused;
        }
        let mut evicted = Vec::new();
        while self.used + bytes > self.budget {
            let Some(victim) = self
                .entries
                .iter()
                .filter(|(i, _)| Some(**i) != keep)
                .min_by_key(|(_, e)| e.last_used)
                .map(|(i, _)| *i)
            else {
                break;
            };
            if let Some(e) = self.entries.remove(&victim) {
                self.used -= e.bytes;
            }
            evicted.push(victim);
        }
        self.clock += 1;
        self.used += bytes;
        self.entries.insert(
            index,
            Entry {
                item,
                bytes,
                last_used: self.clock,
            },
        );
        Admission::Stored { evicted }
    }

    /// Removes a step (its file changed or failed).
    pub fn remove(&mut self, index: usize) -> Option<T> {
        let e = self.entries.remove(&index)?;
        self.used -= e.bytes;
        Some(e.item)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug)]
    struct Fake(u64);

    impl Resident for Fake {
        fn bytes(&self) -> u64 {
            self.0
        }
    }

    #[test]
    fn evicts_least_recently_used_first_and_never_the_kept_step() {
        let mut pool = StepPool::new(300);
        for i in 0..3 {
            assert_eq!(
                pool.insert(i, Fake(100), None),
                Admission::Stored { evicted: vec![] }
            );
        }
        assert_eq!(pool.used(), 300);
        // Step 0 is used again: 1 is now the oldest.
        assert!(pool.get(0).is_some());
        assert_eq!(
            pool.insert(3, Fake(100), None),
            Admission::Stored { evicted: vec![1] }
        );
        // 2 is oldest, but it is displayed: 0 goes instead.
        assert_eq!(
            pool.insert(4, Fake(100), Some(2)),
            Admission::Stored { evicted: vec![0] }
        );
        assert!(pool.contains(2));
        // A step larger than the budget beside the displayed one is refused, nothing evicted.
        assert_eq!(pool.insert(5, Fake(250), Some(2)), Admission::Refused);
        assert_eq!(pool.len(), 3);
        // Two steps go for one large one.
        assert_eq!(
            pool.insert(6, Fake(200), Some(2)),
            Admission::Stored {
                evicted: vec![3, 4]
            }
        );
        assert_eq!(pool.used(), 300);
        let mut held: Vec<usize> = pool.indices().collect();
        held.sort();
        assert_eq!(held, vec![2, 6]);
    }

    #[test]
    fn nearest_and_replacement() {
        let mut pool = StepPool::new(1000);
        pool.insert(10, Fake(100), None);
        pool.insert(20, Fake(100), None);
        assert_eq!(pool.nearest(14), Some(10));
        assert_eq!(pool.nearest(15), Some(10));
        assert_eq!(pool.nearest(16), Some(20));
        pool.insert(10, Fake(300), None);
        assert_eq!(pool.used(), 400);
        assert_eq!(pool.remove(10).map(|f| f.0), Some(300));
        assert_eq!(pool.used(), 100);
        assert_eq!(StepPool::<Fake>::new(10).nearest(3), None);
    }
}
