//! Who may feed the independent watchdog: every part of the firmware that must keep running
//! checks in, and the watchdog is fed only when all of them have since the last feed. Fed from
//! the 10 kHz interrupt alone (before), a hung thread-mode task — the command port, the
//! telemetry writer — was never caught: the interrupt ran on, fed the watchdog, and the board
//! kept switching with no commands read (the 200 ms command timeout still disarms, but a
//! telemetry writer stuck in a loop, or a command task stuck with the bridge disarmed, stays
//! hung for ever).
//!
//! [`CheckIn`] is one atomic word of bits, one per participant (at most 32). Each participant
//! calls [`CheckIn::check_in`] from its own context (a relaxed `fetch_or`, lock-free: the
//! Cortex-M4 has LDREX/STREX); the feeder — the interrupt, which feeds every tick as before —
//! calls [`CheckIn::take_if_all`], which clears the bits and returns true only when every
//! expected bit was set. So the feeder feeds at the rate of the slowest participant: a task
//! that checks in every 100 µs–1 ms keeps the 2 ms watchdog fed; one that stops for longer
//! than the watchdog's period resets the board, into the idle boot with `watchdog_reset`
//! latched. The interrupt is a participant too (its own check-in, so a feeder stuck elsewhere
//! is not mistaken for a live interrupt).
//!
//! Plain data, no allocation; `AtomicU32` from core (a `static` on the board). On targets
//! without atomic read-modify-write (thumbv6m) a glue would guard it with a critical section.

use core::sync::atomic::{AtomicU32, Ordering};

/// Participants' check-ins since the last feed.
#[derive(Debug)]
pub struct CheckIn {
    seen: AtomicU32,
    expected: u32,
}

/// One participant's bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Participant(u32);

impl Participant {
    /// The participant numbered `n` (0–31).
    pub const fn new(n: u8) -> Self {
        assert!(n < 32);
        Self(1 << n)
    }
}

/// The board's participants.
pub mod participants {
    use super::Participant;
    /// The 10 kHz control interrupt (checks in every tick it completes).
    pub const CONTROL_ISR: Participant = Participant::new(0);
    /// The command task (checks in every pass of its loop, bytes or none).
    pub const COMMAND_TASK: Participant = Participant::new(1);
    /// The telemetry writer (checks in every pass, frames or none).
    pub const TELEMETRY_TASK: Participant = Participant::new(2);
    /// All three.
    pub const ALL: [Participant; 3] = [CONTROL_ISR, COMMAND_TASK, TELEMETRY_TASK];
}

impl CheckIn {
    /// Expects `participants` (a `const`: usable for a `static`).
    pub const fn new(participants: &[Participant]) -> Self {
        let mut expected = 0;
        let mut k = 0;
        while k < participants.len() {
            expected |= participants[k].0;
            k += 1;
        }
        Self { seen: AtomicU32::new(0), expected }
    }

    /// `p` is alive (called from its own context, any priority).
    #[inline]
    pub fn check_in(&self, p: Participant) {
        self.seen.fetch_or(p.0, Ordering::Relaxed);
    }

    /// Whether every expected participant has checked in since the last feed (without
    /// consuming the check-ins).
    #[inline]
    pub fn may_feed(&self) -> bool {
        self.seen.load(Ordering::Relaxed) & self.expected == self.expected
    }

    /// For the feeder: true (feed now) when every expected participant has checked in since
    /// the last time this returned true; the check-ins are then consumed. False leaves them.
    #[inline]
    pub fn take_if_all(&self) -> bool {
        let expected = self.expected;
        self.seen
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |s| (s & expected == expected).then_some(0))
            .is_ok()
    }

    /// The expected participants that have not checked in since the last feed (their bits).
    pub fn missing(&self) -> u32 {
        self.expected & !self.seen.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::participants::*;
    use super::*;

    /// The board's loop in ticks of 100 µs: the interrupt checks in and tries to feed every
    /// tick, the command task every `cmd` ticks, the telemetry writer every `tlm` ticks (None:
    /// hung from `hang_at`). Returns the tick at which the 2 ms watchdog (20 ticks) would
    /// fire, if it does within `ticks`.
    fn run(cmd: u32, tlm: u32, hang_at: Option<u32>, ticks: u32) -> Option<u32> {
        let w = CheckIn::new(&ALL);
        let mut since_feed = 0;
        for t in 0..ticks {
            if t % cmd == 0 {
                w.check_in(COMMAND_TASK);
            }
            if t % tlm == 0 && hang_at.is_none_or(|h| t < h) {
                w.check_in(TELEMETRY_TASK);
            }
            w.check_in(CONTROL_ISR);
            if w.take_if_all() {
                since_feed = 0;
            } else {
                since_feed += 1;
                if since_feed >= 20 {
                    return Some(t);
                }
            }
        }
        None
    }

    #[test]
    fn fed_only_when_every_participant_has_checked_in() {
        let w = CheckIn::new(&ALL);
        assert!(!w.may_feed() && !w.take_if_all());
        w.check_in(CONTROL_ISR);
        w.check_in(COMMAND_TASK);
        assert!(!w.may_feed(), "telemetry has not checked in");
        assert_eq!(w.missing(), 1 << 2);
        assert!(!w.take_if_all());
        w.check_in(TELEMETRY_TASK);
        assert!(w.may_feed());
        assert!(w.take_if_all());
        // Consumed: the next feed needs all three again.
        assert!(!w.may_feed() && !w.take_if_all());
        assert_eq!(w.missing(), 0b111);
        // A participant outside the expected set changes nothing.
        let two = CheckIn::new(&[CONTROL_ISR, COMMAND_TASK]);
        two.check_in(CONTROL_ISR);
        two.check_in(TELEMETRY_TASK);
        assert!(!two.may_feed());
        two.check_in(COMMAND_TASK);
        assert!(two.take_if_all());
    }

    #[test]
    fn live_tasks_keep_the_watchdog_fed_and_a_hung_one_is_caught() {
        // Command task every 1 ms, telemetry every 0.5 ms: fed, never fires in 1 s.
        assert_eq!(run(10, 5, None, 10_000), None);
        // The telemetry writer hangs at 0.5 s: the watchdog fires 2 ms after its last
        // check-in was consumed (it checked in at tick 4995; that feed was at tick 5000 at the
        // latest, the command task's).
        let fired = run(10, 5, Some(5000), 10_000).expect("a hung telemetry task was not caught");
        assert!((5019..=5021).contains(&fired), "fired at tick {fired}");
        // A task slower than the watchdog (every 2.5 ms) is a hang too.
        assert!(run(25, 5, None, 10_000).is_some());
        // The interrupt alone (as before) would have fed it: every tick takes its own bit.
        let isr_only = CheckIn::new(&[CONTROL_ISR]);
        isr_only.check_in(CONTROL_ISR);
        assert!(isr_only.take_if_all());
    }
}
