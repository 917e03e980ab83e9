//! [`Worker`]: heavy work (inference, PnP, decoding) on its own thread, fed through a slot of
//! capacity 1 where the newest input replaces one still waiting, so the async side never
//! blocks and the worker always takes the freshest frame.

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use crate::metrics::Metrics;

#[derive(Debug)]
struct State<I> {
    waiting: Option<I>,
    closed: bool,
}

#[derive(Debug)]
struct Slot<I> {
    state: Mutex<State<I>>,
    ready: Condvar,
}

/// A named worker thread running `work` on each input, newest first.
#[derive(Debug)]
pub struct Worker<I> {
    slot: Arc<Slot<I>>,
    metrics: Arc<Metrics>,
    thread: Option<JoinHandle<()>>,
}

impl<I: Send + 'static> Worker<I> {
    /// Starts the thread `name`. `work` runs on it for every input taken from the slot.
    pub fn spawn(
        name: &str,
        metrics: Arc<Metrics>,
        mut work: impl FnMut(I) + Send + 'static,
    ) -> std::io::Result<Self> {
        let slot = Arc::new(Slot {
            state: Mutex::new(State {
                waiting: None,
                closed: false,
            }),
            ready: Condvar::new(),
        });
        let thread_slot = slot.clone();
        let thread_metrics = metrics.clone();
        let thread = std::thread::Builder::new()
            .name(name.to_owned())
            .spawn(move || {
                while let Some(input) = take(&thread_slot) {
                    thread_metrics.set_queue_depth(0);
                    work(input);
                }
            })?;
        Ok(Self {
            slot,
            metrics,
            thread: Some(thread),
        })
    }

    /// Hands `input` to the worker without blocking. An input still waiting is replaced and
    /// counted as dropped; it is returned.
    pub fn submit(&self, input: I) -> Option<I> {
        submit_to(&self.slot, &self.metrics, input)
    }

    /// A cloneable handle that submits to this worker from anywhere (e.g. a Zenoh subscriber
    /// callback on the bus's receive thread, so no async task sits between the bus and the
    /// worker). Inputs submitted after [`Self::shutdown`] are discarded (returned).
    pub fn submitter(&self) -> Submitter<I> {
        Submitter {
            slot: self.slot.clone(),
            metrics: self.metrics.clone(),
        }
    }

    /// Stops taking inputs (one still waiting is discarded) and waits for the current one to
    /// finish. Returns false when the work panicked.
    pub fn shutdown(mut self) -> bool {
        self.close();
        self.thread
            .take()
            .is_none_or(|thread| thread.join().is_ok())
    }

    fn close(&self) {
        let mut state = self
            .slot
            .state
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        state.closed = true;
        state.waiting = None;
        drop(state);
        self.slot.ready.notify_all();
    }
}

/// Submits to a [`Worker`] (see [`Worker::submitter`]).
#[derive(Debug)]
pub struct Submitter<I> {
    slot: Arc<Slot<I>>,
    metrics: Arc<Metrics>,
}

impl<I> Clone for Submitter<I> {
    fn clone(&self) -> Self {
        Self {
            slot: self.slot.clone(),
            metrics: self.metrics.clone(),
        }
    }
}

impl<I> Submitter<I> {
    /// [`Worker::submit`].
    pub fn submit(&self, input: I) -> Option<I> {
        submit_to(&self.slot, &self.metrics, input)
    }
}

fn submit_to<I>(slot: &Slot<I>, metrics: &Metrics, input: I) -> Option<I> {
    let replaced = {
        let mut state = slot.state.lock().unwrap_or_else(PoisonError::into_inner);
        if state.closed {
            return Some(input);
        }
        state.waiting.replace(input)
    };
    slot.ready.notify_one();
    metrics.set_queue_depth(1);
    if replaced.is_some() {
        metrics.frame_dropped();
    }
    replaced
}

impl<I> Drop for Worker<I> {
    fn drop(&mut self) {
        let mut state = self
            .slot
            .state
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        state.closed = true;
        drop(state);
        self.slot.ready.notify_all();
    }
}

/// The next input, or `None` once closed.
fn take<I>(slot: &Slot<I>) -> Option<I> {
    let mut state = slot.state.lock().unwrap_or_else(PoisonError::into_inner);
    loop {
        if state.closed {
            return None;
        }
        if let Some(input) = state.waiting.take() {
            return Some(input);
        }
        state = slot
            .ready
            .wait(state)
            .unwrap_or_else(PoisonError::into_inner);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Duration;

    #[test]
    fn newest_input_replaces_the_waiting_one() {
        let metrics = Arc::new(Metrics::new());
        let (started_tx, started_rx) = mpsc::channel();
        let (release_tx, release_rx) = mpsc::channel::<()>();
        let (done_tx, done_rx) = mpsc::channel();
        let worker = Worker::spawn("test-worker", metrics.clone(), move |input: u32| {
            started_tx.send(input).unwrap();
            release_rx.recv().unwrap();
            done_tx.send(input).unwrap();
        })
        .unwrap();

        assert_eq!(worker.submit(1), None);
        assert_eq!(started_rx.recv_timeout(Duration::from_secs(5)).unwrap(), 1);
        // The worker is busy with 1: 2 waits, 3 replaces it, 4 replaces 3.
        assert_eq!(worker.submit(2), None);
        assert_eq!(worker.submit(3), Some(2));
        assert_eq!(worker.submit(4), Some(3));
        release_tx.send(()).unwrap();
        assert_eq!(started_rx.recv_timeout(Duration::from_secs(5)).unwrap(), 4);
        release_tx.send(()).unwrap();
        let done: Vec<u32> = done_rx.iter().take(2).collect();
        assert_eq!(done, [1, 4]);
        assert!(
            metrics
                .encode()
                .contains("conesight_frames_dropped_total 2")
        );
        assert!(worker.shutdown());
    }

    #[test]
    fn submitters_feed_the_same_slot_from_other_threads_and_stop_at_shutdown() {
        let metrics = Arc::new(Metrics::new());
        let (done_tx, done_rx) = mpsc::channel();
        let worker = Worker::spawn("test-submitter", metrics, move |input: u32| {
            done_tx.send(input).unwrap();
        })
        .unwrap();
        let submitter = worker.submitter();
        let other = submitter.clone();
        std::thread::spawn(move || other.submit(7)).join().unwrap();
        assert_eq!(done_rx.recv_timeout(Duration::from_secs(5)).unwrap(), 7);
        assert_eq!(submitter.submit(8), None);
        assert_eq!(done_rx.recv_timeout(Duration::from_secs(5)).unwrap(), 8);
        assert!(worker.shutdown());
        // After shutdown an input is handed back, not left in a slot nobody reads.
        assert_eq!(submitter.submit(9), Some(9));
    }
}
