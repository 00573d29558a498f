//! What passes between libfreenect's event thread and the async caller:
//! the bounded frame queue, and one-shot replies to commands. Both wake the
//! waiting task through its [`Waker`], so they work under any executor.

use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use super::error::KinectError;
use crate::error::ErrorKind;
use crate::sensor::DepthFrame;

/// Locks, going on after a panic elsewhere: every value behind these locks is
/// valid after any partial update (whole frames are pushed and popped).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|e| e.into_inner())
}

#[derive(Debug, Default)]
struct FrameState {
    frames: VecDeque<DepthFrame>,
    /// Frames thrown away, oldest first, because the queue was full.
    dropped: u64,
    /// Frames the callback received.
    received: u64,
    /// The task waiting in `next_frame`, and since when.
    waker: Option<Waker>,
    waiting_since: Option<Instant>,
    /// Set by the event thread when the waiter has waited too long.
    timed_out: Option<Duration>,
    /// Set once the event loop has ended; served after the queued frames.
    ended: Option<KinectError>,
}

/// Frames from the depth callback to `next_frame`: at most `capacity`, the
/// oldest dropped (and counted) when a new one arrives into a full queue.
#[derive(Debug)]
pub(crate) struct FrameQueue {
    capacity: usize,
    state: Mutex<FrameState>,
}

impl FrameQueue {
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            state: Mutex::new(FrameState::default()),
        }
    }

    /// Called by the depth callback, on the event thread.
    pub(crate) fn push(&self, frame: DepthFrame) {
        let waker = {
            let mut state = lock(&self.state);
            state.received += 1;
            while state.frames.len() >= self.capacity {
                state.frames.pop_front();
                state.dropped += 1;
            }
            state.frames.push_back(frame);
            state.waiting_since = None;
            state.waker.take()
        };
        if let Some(w) = waker {
            w.wake();
        }
    }

    /// Marks the stream ended (the first reason is kept); waiters wake.
    pub(crate) fn end(&self, reason: KinectError) {
        let waker = {
            let mut state = lock(&self.state);
            state.ended.get_or_insert(reason);
            state.waker.take()
        };
        if let Some(w) = waker {
            w.wake();
        }
    }

    /// Whether the stream has ended.
    pub(crate) fn has_ended(&self) -> bool {
        lock(&self.state).ended.is_some()
    }

    /// Called by the event thread: a waiter that has waited longer than
    /// `timeout` for a frame is woken with a timeout.
    pub(crate) fn check_timeout(&self, timeout: Duration) {
        let waker = {
            let mut state = lock(&self.state);
            match state.waiting_since {
                Some(since) if since.elapsed() >= timeout && state.frames.is_empty() => {
                    state.waiting_since = None;
                    state.timed_out = Some(timeout);
                    state.waker.take()
                }
                _ => None,
            }
        };
        if let Some(w) = waker {
            w.wake();
        }
    }

    /// The oldest queued frame; else the end of the stream; else pending.
    pub(crate) fn poll_frame(&self, cx: &mut Context<'_>) -> Poll<Result<DepthFrame, KinectError>> {
        let mut state = lock(&self.state);
        if let Some(frame) = state.frames.pop_front() {
            state.waiting_since = None;
            state.timed_out = None;
            return Poll::Ready(Ok(frame));
        }
        if let Some(reason) = &state.ended {
            return Poll::Ready(Err(reason.clone()));
        }
        if let Some(timeout) = state.timed_out.take() {
            return Poll::Ready(Err(KinectError::new(
                ErrorKind::Timeout,
                format!(
                    "no depth frame from the Kinect within {:.1} s",
                    timeout.as_secs_f64()
                ),
            )));
        }
        state.waiting_since.get_or_insert_with(Instant::now);
        state.waker = Some(cx.waker().clone());
        Poll::Pending
    }

    /// A caller has stopped waiting (its future was dropped): forget its
    /// waker and its wait, so that a timeout of that wait does not fail the
    /// next one.
    pub(crate) fn cancel_wait(&self) {
        let mut state = lock(&self.state);
        state.waker = None;
        state.waiting_since = None;
        state.timed_out = None;
    }

    /// The next frame, as a future that forgets its wait when dropped.
    pub(crate) fn next_frame(&self) -> NextFrame<'_> {
        NextFrame(self)
    }

    /// Throws away the queued frames; returns how many.
    pub(crate) fn clear(&self) -> usize {
        let mut state = lock(&self.state);
        let n = state.frames.len();
        state.frames.clear();
        n
    }

    /// (frames received by the callback, frames dropped from a full queue).
    pub(crate) fn counts(&self) -> (u64, u64) {
        let state = lock(&self.state);
        (state.received, state.dropped)
    }
}

/// The future of [`FrameQueue::next_frame`].
#[derive(Debug)]
pub(crate) struct NextFrame<'a>(&'a FrameQueue);

impl Future for NextFrame<'_> {
    type Output = Result<DepthFrame, KinectError>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        self.0.poll_frame(cx)
    }
}

impl Drop for NextFrame<'_> {
    fn drop(&mut self) {
        self.0.cancel_wait();
    }
}

#[derive(Debug)]
struct Slot<T> {
    value: Option<T>,
    closed: bool,
    waker: Option<Waker>,
}

/// The sending half of a one-shot reply; dropping it unsent closes the reply.
#[derive(Debug)]
pub(crate) struct ReplySender<T>(Arc<Mutex<Slot<T>>>);

/// The receiving half: a future of the value, or `None` if the sender was
/// dropped without sending (the event thread is gone).
#[derive(Debug)]
pub(crate) struct Reply<T>(Arc<Mutex<Slot<T>>>);

pub(crate) fn reply<T>() -> (ReplySender<T>, Reply<T>) {
    let slot = Arc::new(Mutex::new(Slot {
        value: None,
        closed: false,
        waker: None,
    }));
    (ReplySender(slot.clone()), Reply(slot))
}

impl<T> ReplySender<T> {
    pub(crate) fn send(self, value: T) {
        let waker = {
            let mut slot = lock(&self.0);
            slot.value = Some(value);
            slot.waker.take()
        };
        if let Some(w) = waker {
            w.wake();
        }
        // Drop then only marks it closed; the value is already there.
    }
}

impl<T> Drop for ReplySender<T> {
    fn drop(&mut self) {
        let waker = {
            let mut slot = lock(&self.0);
            slot.closed = true;
            slot.waker.take()
        };
        if let Some(w) = waker {
            w.wake();
        }
    }
}

impl<T> Future for Reply<T> {
    type Output = Option<T>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<T>> {
        let mut slot = lock(&self.0);
        if let Some(value) = slot.value.take() {
            return Poll::Ready(Some(value));
        }
        if slot.closed {
            return Poll::Ready(None);
        }
        slot.waker = Some(cx.waker().clone());
        Poll::Pending
    }
}
