//! What subscribers get: [`Notice`]s, queued per subscriber ([`Subscription`]) by the
//! driver and read by a task on its thread.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::future::poll_fn;
use std::rc::Rc;
use std::task::{Poll, Waker};

use comms::{Entry, Key, Value};

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
    pub(crate) queue: VecDeque<Notice>,
    pub(crate) capacity: usize,
    pub(crate) lagged: u64,
    pub(crate) waker: Option<Waker>,
    pub(crate) closed: bool,
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

/// Notices for one pattern; see [`crate::Handle::subscribe`].
pub struct Subscription {
    pub(crate) queue: Rc<RefCell<SubQueue>>,
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
