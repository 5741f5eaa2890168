//! The bridge's master output enable (the timer's MOE bit), written as rarely as possible: a
//! hardware break clears MOE asynchronously, and a write of 1 on a later tick, between reading
//! the break flags and writing the bit, would switch the bridge back on after a short break
//! pulse. So MOE is written 1 only on the tick that arms, and only when no break flag is
//! pending; on every other armed tick it is read back, and a 0 there means the hardware took
//! the outputs off (a break whose flag the firmware has not seen yet, or any other cause):
//! the drive latches `bridge_break`.

/// What to do with MOE this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GateAction {
    /// Leave it alone (on, as read back at the tick's start).
    Hold,
    /// Write 1: the arming tick, no break flag pending.
    Enable,
    /// Write 0.
    Disable,
}

/// Whether the firmware has set MOE and not cleared it since.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OutputGate {
    on: bool,
}

impl OutputGate {
    /// Off (MOE is 0 at reset).
    pub const fn new() -> Self {
        Self { on: false }
    }

    /// Whether the firmware holds the outputs on.
    pub fn is_on(&self) -> bool {
        self.on
    }

    /// At the tick's start, with MOE as read back: true when the firmware held it on and the
    /// hardware has cleared it since. The gate is then off (the next arming must write it).
    #[inline]
    pub fn lost(&mut self, moe: bool) -> bool {
        let lost = self.on && !moe;
        if lost {
            self.on = false;
        }
        lost
    }

    /// After the control tick: `want` is whether the controller enables the bridge,
    /// `break_pending` reads the timer's break flags now (asked only on an arming tick).
    /// Returns what to write; `Disable` with `want` set means the arming was refused for a
    /// pending break.
    #[inline]
    pub fn decide(&mut self, want: bool, break_pending: impl FnOnce() -> bool) -> GateAction {
        match (want, self.on) {
            (true, true) => GateAction::Hold,
            (true, false) if !break_pending() => {
                self.on = true;
                GateAction::Enable
            }
            _ => {
                self.on = false;
                GateAction::Disable
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moe_is_written_one_only_on_the_arming_tick() {
        let mut g = OutputGate::new();
        assert_eq!(g.decide(false, || panic!("flags read while off")), GateAction::Disable);
        assert_eq!(g.decide(true, || false), GateAction::Enable);
        for _ in 0..100 {
            assert!(!g.lost(true));
            assert_eq!(g.decide(true, || panic!("flags read on an armed tick")), GateAction::Hold);
        }
        assert_eq!(g.decide(false, || false), GateAction::Disable);
        assert!(!g.is_on());
    }

    #[test]
    fn a_pending_break_refuses_the_arming_write() {
        let mut g = OutputGate::new();
        assert_eq!(g.decide(true, || true), GateAction::Disable);
        assert!(!g.is_on());
        // Once the flag is gone, the next arming tick writes it.
        assert_eq!(g.decide(true, || false), GateAction::Enable);
    }

    #[test]
    fn moe_cleared_by_hardware_while_armed_is_seen_and_not_undone() {
        let mut g = OutputGate::new();
        g.decide(true, || false);
        assert!(g.lost(false), "MOE read back 0 while held on must be reported");
        // Reported once; the drive then disarms (Disable), never writes 1 on this path.
        assert!(!g.lost(false));
        assert_eq!(g.decide(false, || false), GateAction::Disable);
        // While disarmed a 0 is expected, not a loss.
        assert!(!g.lost(false));
    }
}
