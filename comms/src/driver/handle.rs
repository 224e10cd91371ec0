//! The in-process API for Rust robot software: set, get, post, subscribe.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::future::poll_fn;
use std::rc::Rc;
use std::task::{Poll, Waker};
use std::time::Duration;

use crate::blackboard::{Entry, SetError};
use crate::key::{Key, KeyError};
use crate::pattern::{Pattern, PatternError};
use crate::replica::PostError;
use crate::stats::{PeerInfo, Stats};
use crate::time::Instant;
use crate::value::Value;

use super::{Inner, IoStats};

/// Something a subscription reports.
#[derive(Clone, Debug, PartialEq)]
pub enum Notice {
    /// A matching binding was inserted or changed (key as stored: `n.var.x`,
    /// `local.var.x`).
    Changed {
        /// The key.
        key: Key,
        /// The binding as it is now.
        entry: Entry,
    },
    /// A teammate's message on a matching `n.talk.queue`, in order, exactly once.
    Talk {
        /// The sender.
        from: u8,
        /// The queue path.
        queue: String,
        /// Its sequence number.
        seq: u64,
        /// The message.
        value: Value,
    },
    /// Messages `first..=last` of a matching queue could not be recovered.
    TalkLost {
        /// The sender.
        from: u8,
        /// The queue path.
        queue: String,
        /// First lost sequence number.
        first: u64,
        /// Last lost sequence number.
        last: u64,
    },
    /// The subscriber fell behind: this many older notices were dropped.
    Lagged(u64),
}

/// A subscriber's queue, shared with the driver.
pub(crate) struct SubQueue {
    pub(crate) pattern: Pattern,
    queue: VecDeque<Notice>,
    capacity: usize,
    lagged: u64,
    waker: Option<Waker>,
    closed: bool,
}

impl SubQueue {
    pub(crate) fn push(&mut self, notice: Notice) {
        if self.queue.len() >= self.capacity {
            self.queue.pop_front();
            self.lagged += 1;
        }
        self.queue.push_back(notice);
        if let Some(w) = self.waker.take() {
            w.wake();
        }
    }

    pub(crate) fn close(&mut self) {
        self.closed = true;
        if let Some(w) = self.waker.take() {
            w.wake();
        }
    }
}

/// Notices for one pattern; see [`Handle::subscribe`].
pub struct Subscription {
    queue: Rc<RefCell<SubQueue>>,
}

impl Subscription {
    /// The next notice; `None` once the driver has stopped and everything was read.
    pub async fn next(&mut self) -> Option<Notice> {
        poll_fn(|cx| {
            let mut q = self.queue.borrow_mut();
            if q.lagged > 0 {
                let n = std::mem::take(&mut q.lagged);
                return Poll::Ready(Some(Notice::Lagged(n)));
            }
            if let Some(n) = q.queue.pop_front() {
                return Poll::Ready(Some(n));
            }
            if q.closed {
                return Poll::Ready(None);
            }
            q.waker = Some(cx.waker().clone());
            Poll::Pending
        })
        .await
    }

    /// The next notice if one is waiting, without waiting.
    pub fn try_next(&mut self) -> Option<Notice> {
        let mut q = self.queue.borrow_mut();
        if q.lagged > 0 {
            return Some(Notice::Lagged(std::mem::take(&mut q.lagged)));
        }
        q.queue.pop_front()
    }
}

/// Counters of a running driver.
#[derive(Clone, Debug, PartialEq)]
pub struct DriverStats {
    /// The replica's protocol counters.
    pub replica: Stats,
    /// The socket layer's counters.
    pub io: IoStats,
    /// Every robot heard so far.
    pub peers: Vec<PeerInfo>,
    /// The driver's clock now (to age `PeerInfo::last_heard`).
    pub now: Instant,
}

/// A cheap, cloneable handle to a driver's replica, for tasks on the driver's thread.
/// Every call is synchronous: a `set` or `post` has sent its frame when it returns.
#[derive(Clone)]
pub struct Handle {
    inner: Rc<RefCell<Inner>>,
}

impl Handle {
    pub(super) fn new(inner: Rc<RefCell<Inner>>) -> Handle {
        Handle { inner }
    }

    /// This robot's id.
    pub fn robot_id(&self) -> u8 {
        self.inner.borrow().replica.robot_id()
    }

    /// The driver's clock: the timeline of every entry's `stamp`.
    pub fn now(&self) -> Instant {
        self.inner.borrow().clock.now()
    }

    /// Sets `local.var.x`, `*.var.x` or `<own id>.var.x`; a global value is published
    /// before this returns.
    pub fn set(&self, key: &str, value: impl Into<Value>) -> Result<(), SetError> {
        let mut inner = self.inner.borrow_mut();
        let now = inner.clock.now();
        inner.replica.set(now, key, value.into())?;
        inner.pump();
        Ok(())
    }

    /// Several writes sent together: the replica packs them into as few frames as the
    /// MTU allows, sent when `f` returns (a single [`Handle::set`] sends at once, which
    /// is best for latency and worst for throughput).
    pub fn batch<R>(&self, f: impl FnOnce(&mut Batch<'_>) -> R) -> R {
        let mut inner = self.inner.borrow_mut();
        let now = inner.clock.now();
        let result = f(&mut Batch {
            inner: &mut inner,
            now,
        });
        inner.pump();
        result
    }

    /// Posts a message to this robot's `*.talk.<queue>`; returns its sequence number.
    pub fn post(&self, key: &str, value: impl Into<Value>) -> Result<u64, PostError> {
        let mut inner = self.inner.borrow_mut();
        let now = inner.clock.now();
        let seq = inner.replica.post(now, key, value.into())?;
        inner.pump();
        Ok(seq)
    }

    /// The binding for `key` (`*.var.x`: the newest copy), cloned.
    pub fn get(&self, key: &str) -> Result<Option<Entry>, KeyError> {
        Ok(self.inner.borrow().replica.get(key)?.cloned())
    }

    /// [`Handle::get`], only if at most `max_age` old.
    pub fn get_fresher(&self, key: &str, max_age: Duration) -> Result<Option<Entry>, KeyError> {
        let inner = self.inner.borrow();
        let now = inner.clock.now();
        Ok(inner.replica.get_fresher(now, key, max_age)?.cloned())
    }

    /// Every binding matching `pattern` now, in key order.
    pub fn snapshot(&self, pattern: &str) -> Result<Vec<(Key, Entry)>, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        let inner = self.inner.borrow();
        Ok(inner
            .replica
            .iter(&pattern)
            .map(|(k, e)| (k, e.clone()))
            .collect())
    }

    /// Notices for every change of a binding and every talk message matching `pattern`
    /// (`+.var.ball.#`, `+.talk.plan`), from now on.
    pub fn subscribe(&self, pattern: &str) -> Result<Subscription, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        let mut inner = self.inner.borrow_mut();
        let queue = Rc::new(RefCell::new(SubQueue {
            pattern,
            queue: VecDeque::new(),
            capacity: inner.subscriber_backlog,
            lagged: 0,
            waker: None,
            closed: false,
        }));
        inner.subscribers.push(Rc::downgrade(&queue));
        Ok(Subscription { queue })
    }

    /// The counters and peers.
    pub fn stats(&self) -> DriverStats {
        let inner = self.inner.borrow();
        DriverStats {
            replica: inner.replica.stats().clone(),
            io: inner.io,
            peers: inner.replica.peers().collect(),
            now: inner.clock.now(),
        }
    }

    pub(crate) fn inner(&self) -> &Rc<RefCell<Inner>> {
        &self.inner
    }
}

/// Writes collected by [`Handle::batch`].
pub struct Batch<'a> {
    inner: &'a mut Inner,
    now: Instant,
}

impl Batch<'_> {
    /// As [`Handle::set`], sent when the batch ends.
    pub fn set(&mut self, key: &str, value: impl Into<Value>) -> Result<(), SetError> {
        self.inner.replica.set(self.now, key, value.into())
    }

    /// As [`Handle::post`], sent when the batch ends.
    pub fn post(&mut self, key: &str, value: impl Into<Value>) -> Result<u64, PostError> {
        self.inner.replica.post(self.now, key, value.into())
    }
}
