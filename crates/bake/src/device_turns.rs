//! Turns on a device that several steps share: at most a few steps have work queued on it at
//! once, and a waiting step is let on in order, the most pressing first (a step someone waits
//! for, then the earliest). Without turns, every step in flight queues its passes behind every
//! other's, so steps that reach the device together (a batch's first, or a jump among steps
//! baked ahead) all leave it together, late, while the cores wait for them.
//!
//! A step holds a turn from its first submitted pass until it has read its results back: the
//! device's stages call [`device_busy`] before they submit a pass and [`device_idle`] once a
//! read is done, on the thread that [`on_device`] runs the step's stage on. Uploads take no
//! turn: they are brief copies, and a step preparing its inputs between them would hold one
//! while the device has nothing of it to run.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Condvar, Mutex, PoisonError};

/// Where a step stands in the queue for the device: lower goes first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TurnOrder {
    /// 0 for a step someone waits for, 1 for the rest.
    pub rank: u8,
    /// The step's index in its series: earlier steps are needed first.
    pub step: u64,
}

impl TurnOrder {
    /// A step baked ahead of need or by a batch.
    pub fn ahead(step: usize) -> TurnOrder {
        TurnOrder {
            rank: 1,
            step: step as u64,
        }
    }

    /// A step someone waits for.
    pub fn waited(step: usize) -> TurnOrder {
        TurnOrder {
            rank: 0,
            step: step as u64,
        }
    }
}

#[derive(Debug, Default)]
struct Queue {
    /// Steps on the device, with how many turns each holds (a step's parallel parts may
    /// take turns inside one another's: they are the step's one turn).
    on: BTreeMap<TurnOrder, usize>,
    /// Steps waiting, with a ticket that keeps equal orders first come, first served.
    waiting: BTreeSet<(TurnOrder, u64)>,
    tickets: u64,
}

/// Turns on a device that several steps share: at most `at_once` steps with work queued on it,
/// the waiting let on most pressing first ([`TurnOrder`]).
#[derive(Debug)]
pub struct DeviceTurns {
    at_once: usize,
    queue: Mutex<Queue>,
    changed: Condvar,
}

impl DeviceTurns {
    /// Turns for at most `at_once` steps on the device at once (at least one).
    pub fn new(at_once: usize) -> DeviceTurns {
        DeviceTurns {
            at_once: at_once.max(1),
            queue: Mutex::default(),
            changed: Condvar::new(),
        }
    }

    /// Waits for a turn for the step at `order`: given at once where that step holds one,
    /// else once fewer than `at_once` steps hold one and no waiting step goes before it.
    pub(crate) fn take(self: &Arc<Self>, order: TurnOrder) -> DeviceTurn {
        let mut queue = self.queue.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(held) = queue.on.get_mut(&order) {
            *held += 1;
            return DeviceTurn {
                turns: self.clone(),
                order,
            };
        }
        let ticket = (order, queue.tickets);
        queue.tickets += 1;
        queue.waiting.insert(ticket);
        while !(queue.on.len() < self.at_once && queue.waiting.first() == Some(&ticket)) {
            queue = self
                .changed
                .wait(queue)
                .unwrap_or_else(PoisonError::into_inner);
        }
        queue.waiting.remove(&ticket);
        *queue.on.entry(order).or_default() += 1;
        // The next in line may fit too.
        self.changed.notify_all();
        DeviceTurn {
            turns: self.clone(),
            order,
        }
    }
}

/// A step's turn on the device, given back when dropped.
#[derive(Debug)]
pub(crate) struct DeviceTurn {
    turns: Arc<DeviceTurns>,
    order: TurnOrder,
}

impl Drop for DeviceTurn {
    fn drop(&mut self) {
        let mut queue = self
            .turns
            .queue
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(held) = queue.on.get_mut(&self.order) {
            *held -= 1;
            if *held == 0 {
                queue.on.remove(&self.order);
            }
        }
        self.turns.changed.notify_all();
    }
}

thread_local! {
    /// The turns and order of the step whose stage this thread runs ([`on_device`]).
    static STEP: RefCell<Option<(Arc<DeviceTurns>, TurnOrder)>> = const { RefCell::new(None) };
    /// The turn this thread holds for it.
    static HELD: RefCell<Option<DeviceTurn>> = const { RefCell::new(None) };
}

/// Runs `stage` of the step at `order` on this thread with its work on the device in turns
/// (where `turns` is given): a turn it holds at the end (or in a panic) is given back.
pub(crate) fn on_device<R>(
    turns: Option<&Arc<DeviceTurns>>,
    order: TurnOrder,
    stage: impl FnOnce() -> R,
) -> R {
    let Some(turns) = turns else {
        return stage();
    };
    /// Gives back the turn held and puts back the step run before, however the stage ends.
    struct Restore(Option<(Arc<DeviceTurns>, TurnOrder)>);
    impl Drop for Restore {
        fn drop(&mut self) {
            device_idle();
            STEP.with_borrow_mut(|step| *step = self.0.take());
        }
    }
    let _restore = Restore(STEP.with_borrow_mut(|step| step.replace((turns.clone(), order))));
    stage()
}

/// Called before work is submitted to the device: waits for the step's turn where this
/// thread runs a step's stage in turns and holds none.
pub fn device_busy() {
    if HELD.with_borrow(Option::is_some) {
        return;
    }
    if let Some((turns, order)) = STEP.with_borrow(Clone::clone) {
        let turn = turns.take(order);
        HELD.with_borrow_mut(|held| *held = Some(turn));
    }
}

/// Called once results are read back: the work submitted before has run, and the turn is
/// given back.
pub fn device_idle() {
    // Dropped outside the borrow: its drop wakes the waiting.
    let turn = HELD.with_borrow_mut(Option::take);
    drop(turn);
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    use super::*;

    /// Waits until `count` steps wait for a turn.
    fn until_waiting(turns: &DeviceTurns, count: usize) {
        while turns.queue.lock().unwrap().waiting.len() < count {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    #[test]
    fn waiting_steps_go_on_most_pressing_first_and_never_more_than_at_once() {
        let turns = Arc::new(DeviceTurns::new(2));
        let first = turns.take(TurnOrder::ahead(100));
        let second = turns.take(TurnOrder::ahead(101));
        let order = Arc::new(Mutex::new(Vec::new()));
        let (on, most) = (Arc::new(AtomicUsize::new(2)), Arc::new(AtomicUsize::new(2)));
        // Asked in an order that is not the one they should go on in.
        let asked = [
            TurnOrder::ahead(7),
            TurnOrder::ahead(3),
            TurnOrder::waited(9),
            TurnOrder::ahead(5),
        ];
        let mut threads = Vec::new();
        for (k, &o) in asked.iter().enumerate() {
            let (mine, order, on, most) = (turns.clone(), order.clone(), on.clone(), most.clone());
            threads.push(std::thread::spawn(move || {
                let _turn = mine.take(o);
                order.lock().unwrap().push(o);
                let now = on.fetch_add(1, Ordering::SeqCst) + 1;
                most.fetch_max(now, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(20));
                on.fetch_sub(1, Ordering::SeqCst);
            }));
            until_waiting(&turns, k + 1);
        }
        // One turn given back: the waited-for step goes on; then, with both given back, the
        // rest in step order, two at a time.
        on.fetch_sub(1, Ordering::SeqCst);
        drop(first);
        while order.lock().unwrap().is_empty() {
            std::thread::sleep(Duration::from_millis(1));
        }
        on.fetch_sub(1, Ordering::SeqCst);
        drop(second);
        for t in threads {
            t.join().unwrap();
        }
        let order = order.lock().unwrap().clone();
        let expected = [
            TurnOrder::waited(9),
            TurnOrder::ahead(3),
            TurnOrder::ahead(5),
            TurnOrder::ahead(7),
        ];
        assert_eq!(order, expected);
        assert!(
            most.load(Ordering::SeqCst) <= 2,
            "{most:?} steps on at once"
        );
    }

    #[test]
    fn a_step_holding_a_turn_takes_another_at_once() {
        // One turn at once: the step's second (its tree beside its search) would wait for
        // itself forever if it queued.
        let turns = Arc::new(DeviceTurns::new(1));
        let outer = turns.take(TurnOrder::ahead(4));
        let inner = turns.take(TurnOrder::ahead(4));
        drop(outer);
        assert_eq!(
            turns.queue.lock().unwrap().on.get(&TurnOrder::ahead(4)),
            Some(&1)
        );
        drop(inner);
        assert!(turns.queue.lock().unwrap().on.is_empty());
        // Free again for another step.
        drop(turns.take(TurnOrder::ahead(5)));
    }

    #[test]
    fn a_stage_holds_its_turn_from_a_submission_to_the_next_read_and_none_after_it_ends() {
        let turns = Arc::new(DeviceTurns::new(1));
        let on = |turns: &DeviceTurns| turns.queue.lock().unwrap().on.clone();
        let order = TurnOrder::ahead(1);
        on_device(Some(&turns), order, || {
            device_busy();
            device_busy();
            assert_eq!(
                on(&turns).get(&order),
                Some(&1),
                "one turn for two submissions"
            );
            device_idle();
            assert!(on(&turns).is_empty(), "given back once read");
            device_busy();
        });
        assert!(on(&turns).is_empty(), "given back as the stage ended");
        // A stage that panics holding a turn gives it back.
        let panicked = std::panic::catch_unwind(|| {
            on_device(Some(&turns), order, || {
                device_busy();
                panic!("a pass failed");
            })
        });
        assert!(panicked.is_err());
        assert!(on(&turns).is_empty(), "given back in the panic");
        // Outside a stage in turns, nothing is taken.
        device_busy();
        assert!(on(&turns).is_empty());
        device_idle();
    }
}
