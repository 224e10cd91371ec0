//! The in-process API for Rust robot software on the driver's thread: set, get, post,
//! subscribe, watch, guard.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;
use std::time::Duration;

use comms::{
    Entry, Instant, Key, KeyError, Pattern, PatternError, PeerInfo, PostError, Replica, SetError,
    Stats, Value,
};

use crate::guard::{Guard, GuardSlot, ReadOnlySlot};
use crate::notice::{Notice, SubQueue, Subscription};
use crate::state::{run_reactions, Clock, Inner, IoStats, WatchSlot};

/// A reaction registered with [`Handle::watch`]; dropping it stops the reaction.
pub struct Watch {
    _slot: Rc<WatchSlot>,
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
    pub(crate) fn new(inner: Rc<RefCell<Inner>>) -> Handle {
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
        let value = value.into();
        self.write(|replica, now| replica.set(now, key, value))
    }

    /// [`Handle::set`] with a key parsed once ([`Key::parse`]): a program whose keys are
    /// fixed writes them without checking the text again at every write.
    ///
    /// ```no_run
    /// # async fn f(h: driver::Handle) -> Result<(), comms::SetError> {
    /// let heuristic = comms::Key::parse("*.var.machine.heuristic").expect("a valid key");
    /// h.set_key(&heuristic, 2.5)?;
    /// # Ok(()) }
    /// ```
    pub fn set_key(&self, key: &Key, value: impl Into<Value>) -> Result<(), SetError> {
        let value = value.into();
        self.write(|replica, now| replica.set_key(now, key, value))
    }

    /// One write at the clock's now, sent at once, then the reactions it caused.
    fn write(
        &self,
        f: impl FnOnce(&mut Replica, Instant) -> Result<(), SetError>,
    ) -> Result<(), SetError> {
        {
            let mut inner = self.inner.borrow_mut();
            let inner = &mut *inner;
            let now = inner.clock.now();
            f(&mut inner.replica, now)?;
            inner.pump();
        }
        run_reactions(&self.inner);
        Ok(())
    }

    /// Several writes sent together: the replica packs them into as few frames as the
    /// MTU allows, sent when `f` returns (a single [`Handle::set`] sends at once, which
    /// is best for latency and worst for throughput).
    pub fn batch<R>(&self, f: impl FnOnce(&mut Batch<'_>) -> R) -> R {
        let result = {
            let mut inner = self.inner.borrow_mut();
            let now = inner.clock.now();
            let result = f(&mut Batch {
                inner: &mut inner,
                now,
            });
            inner.pump();
            result
        };
        run_reactions(&self.inner);
        result
    }

    /// Runs `f` on the replica itself at the driver's clock, then sends what it queued:
    /// for code that needs the whole sans-IO core (a team layer reading the blackboard
    /// and writing with priority, the budget's headroom, the game clock). `f` must be
    /// short and must not use a [`Handle`].
    pub fn with_replica<R>(&self, f: impl FnOnce(&mut comms::Replica, Instant) -> R) -> R {
        let result = {
            let mut inner = self.inner.borrow_mut();
            let now = inner.clock.now();
            let result = f(&mut inner.replica, now);
            inner.pump();
            result
        };
        run_reactions(&self.inner);
        result
    }

    /// Posts a message to this robot's `*.talk.<queue>`; returns its sequence number.
    pub fn post(&self, key: &str, value: impl Into<Value>) -> Result<u64, PostError> {
        let seq = {
            let mut inner = self.inner.borrow_mut();
            let now = inner.clock.now();
            let seq = inner.replica.post(now, key, value.into())?;
            inner.pump();
            seq
        };
        run_reactions(&self.inner);
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
            queue: VecDeque::new(),
            capacity: inner.subscriber_backlog,
            lagged: 0,
            waker: None,
            closed: false,
        }));
        // Dropped subscriptions the index has not met since go now.
        inner.subscribers.retain(|weak| weak.strong_count() > 0);
        inner.subscribers.insert(pattern, Rc::downgrade(&queue));
        Ok(Subscription { queue })
    }

    /// Runs `reaction` on the driver's task, inside the turn that applied the change,
    /// for every notice [`Handle::subscribe`] would queue for `pattern`. It is the
    /// lowest-latency way to answer a teammate: no hand-off to another task, so a reply
    /// set from the reaction is sent before the driver reads the next datagram.
    ///
    /// The reaction must be short and must not block: the driver receives nothing
    /// while it runs. It may use the handle it is given (set, post, get; a write it
    /// makes may trigger further reactions, which run after it returns). It stops when
    /// the returned [`Watch`] is dropped.
    pub fn watch(
        &self,
        pattern: &str,
        mut reaction: impl FnMut(&Handle, Notice) + 'static,
    ) -> Result<Watch, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        // The shared state knows no handles: it gives the reaction itself, wrapped.
        let slot = Rc::new(WatchSlot {
            reaction: RefCell::new(Box::new(move |inner: &Rc<RefCell<Inner>>, notice| {
                reaction(&Handle::new(inner.clone()), notice)
            })),
        });
        let mut inner = self.inner.borrow_mut();
        inner.watches.retain(|weak| weak.strong_count() > 0);
        inner.watches.insert(pattern, Rc::downgrade(&slot));
        Ok(Watch { _slot: slot })
    }

    /// Puts `check` in front of every relay client's `SETV` of exactly `key` (as the
    /// client writes it, e.g. `local.var.audio.say`): `Ok` lets the write through, `Err`
    /// becomes the client's `ERR` line and nothing is written. It turns a key into a
    /// command with validated arguments. The check runs inside the driver's turn with
    /// the shared state borrowed: it must be short and must not use a [`Handle`]. Writes
    /// through [`Handle::set`] are not checked (the program calls its own code). It stops
    /// when the returned [`Guard`] is dropped.
    pub fn guard(
        &self,
        key: &str,
        check: impl FnMut(&Value) -> Result<(), comms::relay::Rejected> + 'static,
    ) -> Result<Guard, KeyError> {
        let key = Key::parse(key)?;
        let slot = Rc::new(GuardSlot {
            key,
            check: RefCell::new(Box::new(check)),
        });
        self.inner.borrow_mut().guards.push(Rc::downgrade(&slot));
        Ok(Guard::new(slot))
    }

    /// Makes every key matching `pattern` (`local.var.team.#`) the daemon's own while
    /// the returned [`Guard`] lives: a relay client's `SETV` or `SETP` of one gets
    /// `ERR 423` saying that `owner` writes it, nothing is written, and
    /// [`IoStats::relay_read_only_refused`] counts it. For a part of the daemon whose
    /// outputs other programs trust (the team layer, the GameController listener);
    /// writes through a [`Handle`] are not checked. `local.var.huddle.*`, the counters,
    /// is the daemon's own always.
    pub fn reserve(&self, pattern: &str, owner: &'static str) -> Result<Guard, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        let slot = Rc::new(ReadOnlySlot { pattern, owner });
        let mut inner = self.inner.borrow_mut();
        inner.read_only.retain(|g| g.strong_count() > 0);
        inner.read_only.push(Rc::downgrade(&slot));
        Ok(Guard::new(slot))
    }

    /// The league's referee system's figures for the replica's budget: the game clock
    /// (`game_remaining`, when known) and the team's messages left
    /// ([`comms::Replica::set_external_budget`]; `None`: the replica's own accounting).
    pub fn set_external_budget(
        &self,
        game_remaining: Option<Duration>,
        cap: Option<comms::ExternalCap>,
    ) {
        {
            let mut inner = self.inner.borrow_mut();
            let now = inner.clock.now();
            if let Some(remaining) = game_remaining {
                inner.replica.set_game_clock(now, remaining);
            }
            inner.replica.set_external_budget(cap);
            inner.pump();
            // The budget's deadline moved: the driver task may sleep until a later one.
            inner.wake.notify_one();
        }
        run_reactions(&self.inner);
    }

    /// The driver's clock, for threads that stamp what they observe on its timeline.
    pub fn clock(&self) -> Clock {
        self.inner.borrow().clock
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

    /// As [`Handle::set_key`], sent when the batch ends.
    pub fn set_key(&mut self, key: &Key, value: impl Into<Value>) -> Result<(), SetError> {
        self.inner.replica.set_key(self.now, key, value.into())
    }

    /// As [`Handle::post`], sent when the batch ends.
    pub fn post(&mut self, key: &str, value: impl Into<Value>) -> Result<u64, PostError> {
        self.inner.replica.post(self.now, key, value.into())
    }
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;
    use std::net::SocketAddrV4;
    use std::rc::Rc;
    use std::time::Duration;

    use super::*;
    use crate::run::{Driver, DriverConfig};
    use comms::ReplicaConfig;

    fn config(id: u8, group: SocketAddrV4) -> DriverConfig {
        let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
        cfg.socket.group = group;
        cfg
    }

    async fn next_change(sub: &mut Subscription) -> (Key, Value) {
        let wait = tokio::time::timeout(Duration::from_secs(5), async {
            loop {
                if let Some(Notice::Changed { key, entry }) = sub.next().await {
                    return (key, entry.value);
                }
            }
        });
        wait.await.expect("a change within 5 s")
    }

    /// Runs a test's future on a current-thread runtime inside a `LocalSet`, as a
    /// program using the `!Send` driver does.
    fn on_local<F: std::future::Future>(f: F) -> F::Output {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        tokio::task::LocalSet::new().block_on(&rt, f)
    }

    /// A robot program parses its fixed keys once: a write through the parsed key is the
    /// write its text makes (the same binding, the next version, the same refusals).
    #[test]
    fn a_key_parsed_once_writes_what_its_text_writes() {
        on_local(async {
            let group = crate::scratch_group().expect("a scratch group");
            let one = Driver::bind(config(1, group)).expect("robot 1 binds");
            let h = one.handle();
            let pose = Key::parse("*.var.pose").expect("a valid key");
            h.set_key(&pose, 3).expect("robot 1 sets its own key");
            h.set("*.var.pose", 4).expect("the same key as text");
            h.batch(|b| b.set_key(&pose, 5)).expect("in a batch");
            let e = h.get("1.var.pose").expect("valid").expect("stored");
            assert_eq!(
                (e.version, e.value),
                (3, Value::Int(5)),
                "one binding, three writes"
            );
            let theirs = Key::parse("2.var.pose").expect("a valid key");
            assert_eq!(
                h.set_key(&theirs, 1),
                h.set("2.var.pose", 1),
                "robot 2's copy is refused alike"
            );
            assert!(h.set_key(&theirs, 1).is_err());
        });
    }

    /// Robot 2 answers robot 1's question from a watch, inside its driver's turn; its
    /// own write, seen by a second watch, chains a local note; dropping the watch stops
    /// the answers.
    #[test]
    fn a_watch_answers_a_teammate_in_the_drivers_turn() {
        on_local(async {
            let group = crate::scratch_group().expect("a scratch group");
            let one = Driver::bind(config(1, group)).expect("robot 1 binds");
            let two = Driver::bind(config(2, group)).expect("robot 2 binds");
            let (h1, h2) = (one.handle(), two.handle());
            tokio::task::spawn_local(one.run(std::future::pending()));
            tokio::task::spawn_local(two.run(std::future::pending()));

            let answers = h2
                .watch("1.var.question", |h, notice| {
                    if let Notice::Changed { entry, .. } = notice {
                        let Value::Int(q) = entry.value else { return };
                        h.set("*.var.answer", q * 2)
                            .expect("robot 2 sets its own key");
                    }
                })
                .expect("valid pattern");
            let notes = Rc::new(RefCell::new(Vec::new()));
            let seen = notes.clone();
            let _chained = h2
                .watch("2.var.answer", move |h, notice| {
                    if let Notice::Changed { entry, .. } = notice {
                        seen.borrow_mut().push(entry.value.clone());
                        h.set("local.var.last_answer", entry.value)
                            .expect("local key");
                    }
                })
                .expect("valid pattern");
            let mut replies = h1.subscribe("2.var.answer").expect("valid pattern");

            h1.set("*.var.question", 21)
                .expect("robot 1 sets its own key");
            let (key, value) = next_change(&mut replies).await;
            assert_eq!(
                (key.to_string().as_str(), value),
                ("2.var.answer", Value::Int(42)),
                "robot 2's watch answers the question and robot 1 sees it"
            );
            assert_eq!(
                *notes.borrow(),
                vec![Value::Int(42)],
                "a write made by a reaction triggers the reactions watching it"
            );
            assert_eq!(
                h2.get("local.var.last_answer")
                    .expect("valid key")
                    .map(|e| e.value),
                Some(Value::Int(42)),
                "the chained reaction could write through its handle"
            );

            drop(answers);
            h1.set("*.var.question", 5)
                .expect("robot 1 sets its own key");
            let mut questions = h2.subscribe("1.var.question").expect("valid pattern");
            let (_, asked) = next_change(&mut questions).await;
            assert_eq!(asked, Value::Int(5), "robot 2 still hears the question");
            assert_eq!(
                h2.get("2.var.answer").expect("valid key").map(|e| e.value),
                Some(Value::Int(42)),
                "a dropped watch no longer reacts"
            );
        });
    }
}
