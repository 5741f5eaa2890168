//! Watchdog check-in (issue 64 item 3): the 10 kHz interrupt feeds the independent watchdog only
//! while every thread-mode task has checked in within the last [`WINDOW_TICKS`]; a task that
//! hangs (stops returning to the executor, or waits for something that never comes) starves the
//! watchdog, and the board resets into its idle boot with `watchdog_reset` latched.
//!
//! SEAM: a minimal local mechanism, to be replaced by the control crate's check-in struct (being
//! written in parallel in `gma_control`) when the two branches merge; `gma-drive` uses only
//! [`Checkins::check_in`] (tasks) and [`Checkins::may_feed`] (the interrupt's watchdog feed).

use core::sync::atomic::{AtomicU32, Ordering};

/// A thread-mode task that must check in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Task {
    /// The command receiver (checks in after every chunk and at least every
    /// [`COMMAND_IDLE_CHECKIN_MS`] while the line is silent).
    Command = 1 << 0,
    /// The telemetry and reply writer (checks in every loop: ≤ 1 ms at 4 Mbaud).
    Telemetry = 1 << 1,
}

/// Every task's bit.
pub const ALL: u32 = Task::Command as u32 | Task::Telemetry as u32;

/// How long the interrupt goes on feeding without every task's check-in [ticks]: 100 ms, five
/// of the command task's idle check-ins; a load's model build (≈ 2.5 ms) fits many times.
pub const WINDOW_TICKS: u32 = 1000;

/// The command task's check-in period while no byte arrives [ms].
pub const COMMAND_IDLE_CHECKIN_MS: u64 = 20;

/// The check-ins since the interrupt last saw them all.
pub struct Checkins {
    seen: AtomicU32,
}

impl Checkins {
    /// None seen.
    pub const fn new() -> Self {
        Self { seen: AtomicU32::new(0) }
    }

    /// A task's check-in (thread mode).
    pub fn check_in(&self, task: Task) {
        self.seen.fetch_or(task as u32, Ordering::Relaxed);
    }

    /// The interrupt's side, once per tick: whether it may feed the watchdog. `stale` counts the
    /// ticks since all tasks were last seen (the caller's state); once they all have been, the
    /// bits start again from none.
    pub fn may_feed(&self, stale: &mut u32) -> bool {
        if self.seen.load(Ordering::Relaxed) & ALL == ALL {
            self.seen.fetch_and(!ALL, Ordering::Relaxed);
            *stale = 0;
        } else {
            *stale = stale.saturating_add(1);
        }
        *stale <= WINDOW_TICKS
    }

    /// The tasks not seen since the last complete round (for a log).
    pub fn missing(&self) -> u32 {
        ALL & !self.seen.load(Ordering::Relaxed)
    }
}

impl Default for Checkins {
    fn default() -> Self {
        Self::new()
    }
}
