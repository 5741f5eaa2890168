//! Reference generator: the excitations the workbench identifies with (sine with DC bias, chirp,
//! multisine, steps), produced tick by tick without a sine call per tick: each tone is a unit
//! phasor rotated by its per-tick angle (renormalised every tick), the rotation's cos/sin from a
//! short Taylor series (angles ≤ 0.63 rad per tick up to 1 kHz at 10 kHz: error < 1e-7).
//! Square and triangle waves step a 32-bit phase accumulator (one period = 2³², wrapping), so
//! their timing is as exact after days as at the start; there is no time variable to lose
//! resolution or wrap.

/// Most tones of a multisine.
pub const MAX_TONES: usize = 8;

/// A reference waveform in µm (or any unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Waveform {
    /// bias + amplitude · sin(2π f t).
    Sine {
        /// Frequency [Hz].
        freq_hz: f32,
        /// Amplitude.
        amplitude: f32,
        /// DC level.
        bias: f32,
    },
    /// Linear chirp from f0 to f1 over `duration_s`, then holds f1.
    Chirp {
        /// Start frequency [Hz].
        f0_hz: f32,
        /// End frequency [Hz].
        f1_hz: f32,
        /// Sweep time [s].
        duration_s: f32,
        /// Amplitude.
        amplitude: f32,
        /// DC level.
        bias: f32,
    },
    /// Equal-amplitude tones at k·f (k = 1 … `tones`), Schroeder phases, peak ≈ amplitude.
    Multisine {
        /// Fundamental [Hz].
        freq_hz: f32,
        /// Number of tones (≤ [`MAX_TONES`]).
        tones: u8,
        /// Peak amplitude.
        amplitude: f32,
        /// DC level.
        bias: f32,
    },
    /// bias ± amplitude, period 1/f.
    Steps {
        /// Frequency [Hz].
        freq_hz: f32,
        /// Amplitude.
        amplitude: f32,
        /// DC level.
        bias: f32,
    },
    /// bias ± amplitude with linear ramps, period 1/f (starts at bias, rising).
    Triangle {
        /// Frequency [Hz].
        freq_hz: f32,
        /// Amplitude.
        amplitude: f32,
        /// DC level.
        bias: f32,
    },
    /// A constant level.
    Constant {
        /// DC level.
        bias: f32,
    },
}

/// cos θ and sin θ for |θ| ≤ 0.7 (Taylor to θ⁸ / θ⁹).
#[inline]
fn rotation(theta: f32) -> (f32, f32) {
    let t2 = theta * theta;
    let c = 1.0 - t2 / 2.0 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0)));
    let s = theta * (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0))));
    (c, s)
}

/// The generator (waveform, tick, and the tones' phasors).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    wave: Waveform,
    tick_s: f32,
    /// Ticks since the start, saturating: only the chirp's sweep reads it (held at `f1` after
    /// `duration_s`, so saturation changes nothing).
    ticks: u32,
    /// Phase of a square or triangle wave [2⁻³² periods], wrapping.
    phase: u32,
    /// Its step per tick.
    phase_step: u32,
    phasor: [(f32, f32); MAX_TONES],
    step: [(f32, f32); MAX_TONES],
}

impl Reference {
    /// A generator at `tick_s`, phase 0 at tick 0. Frequencies are clamped to below a sixth of
    /// the tick rate (the rotation series' range).
    pub fn new(wave: Waveform, tick_s: f32) -> Self {
        let max_f = 1.0 / (6.0 * tick_s);
        let wave = match wave {
            Waveform::Sine { freq_hz, amplitude, bias } => {
                Waveform::Sine { freq_hz: freq_hz.clamp(0.0, max_f), amplitude, bias }
            }
            Waveform::Chirp { f0_hz, f1_hz, duration_s, amplitude, bias } => Waveform::Chirp {
                f0_hz: f0_hz.clamp(0.0, max_f),
                f1_hz: f1_hz.clamp(0.0, max_f),
                duration_s: duration_s.max(tick_s),
                amplitude,
                bias,
            },
            Waveform::Multisine { freq_hz, tones, amplitude, bias } => {
                let tones = tones.clamp(1, MAX_TONES as u8);
                Waveform::Multisine {
                    freq_hz: freq_hz.clamp(0.0, max_f / tones as f32),
                    tones,
                    amplitude,
                    bias,
                }
            }
            w @ (Waveform::Steps { .. } | Waveform::Triangle { .. } | Waveform::Constant { .. }) => w,
        };
        let mut r = Self {
            wave,
            tick_s,
            ticks: 0,
            phase: 0,
            phase_step: 0,
            phasor: [(1.0, 0.0); MAX_TONES],
            step: [(1.0, 0.0); MAX_TONES],
        };
        let two_pi_t = 2.0 * core::f32::consts::PI * tick_s;
        match wave {
            Waveform::Sine { freq_hz, .. } => r.step[0] = rotation(two_pi_t * freq_hz),
            Waveform::Multisine { freq_hz, tones, .. } => {
                let n = tones as usize;
                for k in 0..n {
                    // Schroeder phase −π k (k+1) / n, set by rotating the start phasor.
                    let ph = -core::f32::consts::PI * ((k * (k + 1)) % (2 * n)) as f32 / n as f32;
                    let (s, c) = model_core::math::sin_cos(ph);
                    r.phasor[k] = (c, s);
                    r.step[k] = rotation(two_pi_t * freq_hz * (k + 1) as f32);
                }
            }
            Waveform::Steps { freq_hz, .. } | Waveform::Triangle { freq_hz, .. } => {
                r.phase_step = phase_step(freq_hz, tick_s);
            }
            _ => {}
        }
        r
    }

    /// The waveform.
    pub fn waveform(&self) -> Waveform {
        self.wave
    }

    /// A sine's frequency [Hz] and its phasor (cos θ, sin θ) at the current tick; `None` for the
    /// other waveforms.
    pub fn fundamental(&self) -> Option<(f32, (f32, f32))> {
        match self.wave {
            Waveform::Sine { freq_hz, .. } => Some((freq_hz, self.phasor[0])),
            _ => None,
        }
    }

    /// The value at the current tick, then advances one tick.
    #[inline]
    pub fn advance(&mut self) -> f32 {
        let phase = self.phase;
        self.phase = phase.wrapping_add(self.phase_step);
        let advance = |z: &mut (f32, f32), w: (f32, f32)| {
            let (c, s) = (z.0 * w.0 - z.1 * w.1, z.0 * w.1 + z.1 * w.0);
            // Renormalise: one Newton step towards |z| = 1 keeps the amplitude exact.
            let g = 1.5 - 0.5 * (c * c + s * s);
            *z = (c * g, s * g);
        };
        match self.wave {
            Waveform::Sine { amplitude, bias, .. } => {
                let v = bias + amplitude * self.phasor[0].1;
                advance(&mut self.phasor[0], self.step[0]);
                v
            }
            Waveform::Chirp { f0_hz, f1_hz, duration_s, amplitude, bias } => {
                let v = bias + amplitude * self.phasor[0].1;
                let t = self.ticks as f32 * self.tick_s;
                self.ticks = self.ticks.saturating_add(1);
                let f = if t < duration_s { f0_hz + (f1_hz - f0_hz) * t / duration_s } else { f1_hz };
                let w = rotation(2.0 * core::f32::consts::PI * self.tick_s * f);
                advance(&mut self.phasor[0], w);
                v
            }
            Waveform::Multisine { amplitude, bias, tones, .. } => {
                let n = tones as usize;
                let mut sum = 0.0;
                for k in 0..n {
                    sum += self.phasor[k].1;
                    let w = self.step[k];
                    advance(&mut self.phasor[k], w);
                }
                // Schroeder multisines peak near 1.6 √n.
                let scale = amplitude / (1.6 * model_core::math::sqrt(n as f32));
                bias + scale * sum
            }
            Waveform::Steps { amplitude, bias, .. } => {
                bias + if phase < HALF_PERIOD { amplitude } else { -amplitude }
            }
            Waveform::Triangle { amplitude, bias, .. } => {
                // Phase shifted a quarter period so that the ramp starts at the bias.
                let frac = phase.wrapping_add(HALF_PERIOD / 2) as f32 * PHASE_UNIT;
                bias + amplitude * (1.0 - 4.0 * (frac - 0.5).abs())
            }
            Waveform::Constant { bias } => bias,
        }
    }

    /// The value `n` ticks ahead without advancing (for feedforward preview). A sine rotates its
    /// phasor `n` steps ahead (a few multiplications every tick, where copying the generator
    /// costs more than the rest of the reference); the other waveforms step a copy.
    pub fn peek_ahead(&self, n: u32) -> f32 {
        if let Waveform::Sine { amplitude, bias, .. } = self.wave {
            let w = self.step[0];
            let (mut c, mut s) = self.phasor[0];
            for _ in 0..n {
                (c, s) = (c * w.0 - s * w.1, c * w.1 + s * w.0);
            }
            return bias + amplitude * s;
        }
        let mut copy = *self;
        for _ in 0..n {
            copy.advance();
        }
        copy.advance()
    }
}

/// Half a period of the phase accumulator.
const HALF_PERIOD: u32 = 1 << 31;
/// One unit of the phase accumulator [periods].
const PHASE_UNIT: f32 = 1.0 / 4_294_967_296.0;

/// The accumulator's step for `freq_hz` at `tick_s` (below a sixth of the tick rate, see
/// [`Reference::new`]): computed in f64 once, so the period is right to 2⁻³² of a tick's phase.
fn phase_step(freq_hz: f32, tick_s: f32) -> u32 {
    let step = freq_hz as f64 * tick_s as f64 * 4_294_967_296.0;
    if step.is_finite() && step > 0.0 && step < 4_294_967_295.0 {
        (step + 0.5) as u32
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sine_peeked_ahead_is_the_value_stepping_gives() {
        let mut r = Reference::new(Waveform::Sine { freq_hz: 230.0, amplitude: 12.5, bias: 20.0 }, 1e-4);
        for _ in 0..10_000 {
            let mut stepped = r;
            for _ in 0..3 {
                stepped.advance();
            }
            let (peeked, want) = (r.peek_ahead(3), stepped.advance());
            assert!((peeked - want).abs() < 1e-4, "peeked {peeked}, stepped {want}");
            r.advance();
        }
    }

    #[test]
    fn sine_matches_the_closed_form_over_many_periods() {
        let mut r = Reference::new(Waveform::Sine { freq_hz: 100.0, amplitude: 12.5, bias: 20.0 }, 1e-4);
        let mut worst = 0.0f64;
        for k in 0..100_000 {
            let v = r.advance() as f64;
            let t = k as f64 * 1e-4;
            let exact = 20.0 + 12.5 * (2.0 * std::f64::consts::PI * 100.0 * t).sin();
            worst = worst.max((v - exact).abs());
        }
        assert!(worst < 2e-3, "max error {worst} over 10 s");
    }

    /// 2²⁵ ticks (56 minutes at 10 kHz) stepped for real. With the time base `ticks as f32 *
    /// tick_s` this failed: past 2²⁴ ticks the f32 time rounds to pairs of ticks and the phase
    /// t·f to 0.03 periods (square edges 46–54 ticks apart, a triangle off by 12 % of its
    /// amplitude), and the u32 tick count wrapped after 5 days. The accumulator has no growing
    /// state; its only error is the step's rounding, 2⁻³³ of a period per tick.
    #[test]
    fn square_and_triangle_keep_their_timing_over_a_long_run() {
        const N: u32 = 1 << 25;
        let tick_s = 1e-4f32;
        let mut sq = Reference::new(Waveform::Steps { freq_hz: 100.0, amplitude: 1.0, bias: 0.0 }, tick_s);
        let mut tri =
            Reference::new(Waveform::Triangle { freq_hz: 100.0, amplitude: 1.0, bias: 0.0 }, tick_s);
        let (mut last, mut since, mut edges, mut worst) = (sq.advance(), 1u32, 0u32, 0.0f64);
        tri.advance();
        for k in 1..N {
            let v = sq.advance();
            if v != last {
                // The f32 tick (1e-4 rounds 2.5e-8 short) makes each half period 50.0000013
                // ticks: the edges fall on the 50th or 51st tick, never elsewhere.
                assert!(since == 50 || since == 51, "square edge at tick {k} after {since} ticks");
                (last, since, edges) = (v, 0, edges + 1);
            }
            since += 1;
            // The closed form at the generator's own frequency: a tick's phase step, rounded
            // once to 2⁻³² of a period (checked below).
            let exact = {
                let frac = (k as f64 * tri.phase_step as f64 / 4_294_967_296.0 + 0.25).fract();
                1.0 - 4.0 * (frac - 0.5).abs()
            };
            worst = worst.max((tri.advance() as f64 - exact).abs());
        }
        assert!((N / 50 - 2..=N / 50).contains(&edges), "{edges} edges in {N} ticks");
        assert!(worst < 1e-5, "triangle off the closed form by {worst} of its amplitude");
        let wanted = 100.0 * tick_s as f64 * 4_294_967_296.0;
        assert!((tri.phase_step as f64 - wanted).abs() <= 0.5, "step {} for {wanted}", tri.phase_step);
        // Across the accumulator's wrap (every period): half a step either side of it, 0.245
        // and 0.255 periods past the rising bias.
        tri.phase = u32::MAX - tri.phase_step / 2;
        let (a, b) = (tri.advance(), tri.advance());
        assert!((a + 0.02).abs() < 1e-3 && (b - 0.02).abs() < 1e-3, "at the wrap: {a}, {b}");
    }

    #[test]
    fn a_chirp_holds_its_end_frequency_past_the_tick_counter_range() {
        let w = Waveform::Chirp { f0_hz: 10.0, f1_hz: 200.0, duration_s: 1.0, amplitude: 1.0, bias: 0.0 };
        let mut r = Reference::new(w, 1e-4);
        r.ticks = u32::MAX - 3;
        let mut held = r;
        held.ticks = 20_000; // past the sweep: f1
        for _ in 0..10 {
            assert_eq!(r.advance(), held.advance());
        }
        assert_eq!(r.ticks, u32::MAX, "the counter saturates");
    }

    #[test]
    fn chirp_steps_and_multisine_are_bounded() {
        for w in [
            Waveform::Chirp { f0_hz: 1.0, f1_hz: 500.0, duration_s: 1.0, amplitude: 10.0, bias: 5.0 },
            Waveform::Steps { freq_hz: 10.0, amplitude: 10.0, bias: 5.0 },
            Waveform::Multisine { freq_hz: 20.0, tones: 8, amplitude: 10.0, bias: 5.0 },
            Waveform::Triangle { freq_hz: 10.0, amplitude: 10.0, bias: 5.0 },
        ] {
            let mut r = Reference::new(w, 1e-4);
            let (mut lo, mut hi) = (f32::MAX, f32::MIN);
            for _ in 0..20_000 {
                let v = r.advance();
                assert!(v.is_finite());
                lo = lo.min(v);
                hi = hi.max(v);
            }
            assert!(hi <= 5.0 + 10.0 * 1.2 && lo >= 5.0 - 10.0 * 1.2, "{w:?}: {lo}..{hi}");
            assert!(hi - lo > 10.0, "{w:?} barely moves: {lo}..{hi}");
        }
        let mut r = Reference::new(Waveform::Steps { freq_hz: 10.0, amplitude: 1.0, bias: 0.0 }, 1e-4);
        assert_eq!(r.peek_ahead(600), -1.0);
        assert_eq!(r.advance(), 1.0);
        // Triangle: bias at t = 0, the peak a quarter period on, the trough at three quarters.
        let mut r = Reference::new(Waveform::Triangle { freq_hz: 10.0, amplitude: 2.0, bias: 1.0 }, 1e-4);
        assert!((r.peek_ahead(250) - 3.0).abs() < 1e-4 && (r.peek_ahead(750) + 1.0).abs() < 1e-4);
        assert!((r.advance() - 1.0).abs() < 1e-6);
    }
}
