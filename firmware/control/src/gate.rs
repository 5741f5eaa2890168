//! The bridge's master output enable (the timer's MOE bit), written as rarely as possible: a
//! hardware break clears MOE asynchronously, and a write of 1 on a later tick, between reading
//! the break flags and writing the bit, would switch the bridge back on after a short break
//! pulse. So MOE is written 1 only on the tick that arms, and only when no break flag is
//! pending (and the flags are read again right after the write, which is undone if one was
//! set meanwhile); on every other armed tick it is read back, and a 0 there means the hardware took
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

    /// Right after an `Enable` write, with the break flags read again: a break pulse that came
    /// and went between the pending check and the write left its flag set, and the write turned
    /// the outputs back on. True: the write must be undone at once (the gate is off again).
    #[inline]
    pub fn undo_enable(&mut self, break_pending: bool) -> bool {
        if break_pending {
            self.on = false;
        }
        break_pending
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
    fn a_break_flag_set_during_the_arming_write_undoes_it() {
        let mut g = OutputGate::new();
        assert_eq!(g.decide(true, || false), GateAction::Enable);
        assert!(g.undo_enable(true), "a flag read after the write must undo it");
        assert!(!g.is_on());
        // Off again: the next armed tick must decide afresh (and reads the flags), not hold.
        assert_eq!(g.decide(true, || true), GateAction::Disable);
        // With no flag after the write the gate stays on.
        assert_eq!(g.decide(true, || false), GateAction::Enable);
        assert!(!g.undo_enable(false));
        assert!(g.is_on());
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
