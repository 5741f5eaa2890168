//! The magnetic stages' runs of one file, kept for parameter sets that differ only downstream.
//!
//! A Levenberg–Marquardt Jacobian moves one parameter at a time. The columns of the mechanics
//! (and of thermal drift and sensor delay), and for every other file each file's own
//! initial-state column, leave the drive → current → field → magnetization part of a run as it
//! was, and that part is most of a run's time (the J–A integration). Kept here, those columns
//! run only the mechanical stages ([`model_core::Actuator::step_mechanical`]); the results are
//! the same bits as a full run's, since the magnetic stages take nothing from downstream.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use model_core::MagneticOutput;

/// Memory one file's memo may hold [bytes]: eleven runs of a 30 000-sample file, one of a
/// 300 000-sample file.
const BUDGET_BYTES: usize = 4 << 20;

/// Recent magnetic-stage runs of one file, by what determines them (least recently used
/// dropped first). Shared by the threads of one fit; dropped with it.
#[derive(Debug, Default)]
pub struct MagneticMemo {
    runs: Mutex<VecDeque<(String, Arc<[MagneticOutput]>)>>,
}

impl MagneticMemo {
    /// The kept run for `key`, now the most recently used.
    pub fn get(&self, key: &str) -> Option<Arc<[MagneticOutput]>> {
        let mut runs = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        let at = runs.iter().position(|(k, _)| k == key)?;
        let entry = runs.remove(at)?;
        let hit = entry.1.clone();
        runs.push_back(entry);
        Some(hit)
    }

    /// How many runs are kept.
    pub fn kept(&self) -> usize {
        self.runs.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    /// Keeps `run` for `key`, dropping the least recently used runs beyond the budget (a run
    /// larger than the budget is not kept).
    pub fn keep(&self, key: String, run: Vec<MagneticOutput>) {
        let capacity = (BUDGET_BYTES / (run.len().max(1) * size_of::<MagneticOutput>())).min(16);
        if capacity == 0 {
            return;
        }
        let mut runs = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        // Two threads may have run the same parameters at once.
        if !runs.iter().any(|(k, _)| *k == key) {
            runs.push_back((key, run.into()));
        }
        while runs.len() > capacity {
            runs.pop_front();
        }
    }
}
