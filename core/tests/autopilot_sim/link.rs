//! One direction of the serial link between the board and the autopilot: every message is
//! delivered after a delay, in the order it was sent (a UART does not reorder). Each message
//! may carry a tag (the autopilot's time stamp in it), for the tests that check the
//! companion's mapping of the autopilot's clock.

use std::collections::VecDeque;

use super::Rng;

/// How long a message takes.
#[derive(Debug, Clone, Copy)]
pub enum LinkDelay {
    /// Always this long, µs.
    Fixed(u64),
    /// 0.5-4 ms for each message (round trips of 1-8 ms), drawn from the time it is sent
    /// (and its place among the messages sent at that same time), not from a shared random
    /// sequence: a message added to the stream (a new STATUSTEXT, say) then leaves the other
    /// messages' delays as they were, and a test's figures do not move with the traffic.
    Random,
}

/// One direction of the link.
pub struct Link {
    delay: LinkDelay,
    /// (arrival time, bytes, tag), in arrival order.
    queue: VecDeque<(u64, Vec<u8>, Option<u64>)>,
    last_arrival: u64,
    /// The send time of the last message and how many were sent at it.
    last_send: (u64, u64),
}

impl Link {
    pub fn new(delay: LinkDelay) -> Self {
        Link {
            delay,
            queue: VecDeque::new(),
            last_arrival: 0,
            last_send: (u64::MAX, 0),
        }
    }

    /// Sends `bytes` at `now`. The delay draws from no shared random sequence (see
    /// [`LinkDelay::Random`]), so a caller's own random sequence does not depend on the traffic.
    pub fn send(&mut self, now: u64, bytes: Vec<u8>, tag: Option<u64>) {
        let index = if self.last_send.0 == now {
            self.last_send.1 + 1
        } else {
            0
        };
        self.last_send = (now, index);
        let delay = match self.delay {
            LinkDelay::Fixed(us) => us,
            LinkDelay::Random => {
                let mut draw = Rng(now ^ index.rotate_left(48) ^ 0x005E_ED0F_114B);
                500 + (draw.uniform() * 3500.0) as u64
            }
        };
        // Never ahead of an earlier message: in order.
        let at = (now + delay).max(self.last_arrival);
        self.last_arrival = at;
        self.queue.push_back((at, bytes, tag));
    }

    /// The next message that has arrived by `now`, with its tag.
    pub fn due(&mut self, now: u64) -> Option<(Vec<u8>, Option<u64>)> {
        if self.queue.front().is_some_and(|(t, _, _)| *t <= now) {
            self.queue.pop_front().map(|(_, bytes, tag)| (bytes, tag))
        } else {
            None
        }
    }

    /// Drops everything under way (the sender lost power).
    pub fn clear(&mut self) {
        self.queue.clear();
    }
}
