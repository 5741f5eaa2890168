//! Units: raw ADC codes become SI quantities once, at the edge, through one calibration.

/// A 12-bit ADC code (0–4095).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct AdcCode(pub u16);

/// Coil current [A].
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
pub struct Amps(pub f32);

/// Voltage [V].
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
pub struct Volts(pub f32);

/// Displacement [µm].
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
pub struct Micrometres(pub f32);

/// Full scale of the 12-bit converter.
pub const ADC_FULL_SCALE: u16 = 4095;

/// Board calibration: the analog front end's scaling, measured once per board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// ADC reference [V].
    pub vref: f32,
    /// Shunt amplifier: output [V] at zero current (mid-rail for a bipolar coil current).
    pub current_zero_v: f32,
    /// Shunt amplifier gain [V/A] (shunt resistance × amplifier gain).
    pub current_v_per_a: f32,
    /// Displacement sensor: output [V] at 0 µm.
    pub displacement_zero_v: f32,
    /// Displacement sensor sensitivity [V/µm].
    pub displacement_v_per_um: f32,
}

impl Calibration {
    /// The reference board (firmware/README.md): 3.3 V reference, 10 mΩ shunt × gain 20
    /// (0.2 V/A) around 1.65 V (±8 A span), eddy-current probe 0–3.3 V over 0–100 µm.
    pub const REFERENCE_BOARD: Calibration = Calibration {
        vref: 3.3,
        current_zero_v: 1.65,
        current_v_per_a: 0.2,
        displacement_zero_v: 0.0,
        displacement_v_per_um: 0.033,
    };

    fn volts(&self, c: AdcCode) -> f32 {
        c.0 as f32 * (self.vref / ADC_FULL_SCALE as f32)
    }

    fn code(&self, v: f32) -> AdcCode {
        let c = v / self.vref * ADC_FULL_SCALE as f32 + 0.5;
        AdcCode(if c <= 0.0 {
            0
        } else if c >= ADC_FULL_SCALE as f32 {
            ADC_FULL_SCALE
        } else {
            c as u16
        })
    }

    /// Coil current from its ADC code.
    #[inline]
    pub fn current(&self, c: AdcCode) -> Amps {
        Amps((self.volts(c) - self.current_zero_v) / self.current_v_per_a)
    }

    /// Displacement from its ADC code.
    #[inline]
    pub fn displacement(&self, c: AdcCode) -> Micrometres {
        Micrometres((self.volts(c) - self.displacement_zero_v) / self.displacement_v_per_um)
    }

    /// The code a current produces (for simulated front ends), saturating at the rails.
    pub fn current_code(&self, i: Amps) -> AdcCode {
        self.code(self.current_zero_v + i.0 * self.current_v_per_a)
    }

    /// The code a displacement produces (for simulated front ends), saturating at the rails.
    pub fn displacement_code(&self, y: Micrometres) -> AdcCode {
        self.code(self.displacement_zero_v + y.0 * self.displacement_v_per_um)
    }
}
