//! The board checks its own configuration (issue 64 item 4): at boot `gma-drive` reads back what
//! the HAL and its own glue wrote to TIM1, ADC1, the IWDG, DBGMCU, SYSCFG, the comparators, the
//! DACs and the pins of the comparator route, and compares each field with [`expected`], a table
//! of register addresses, field masks and values taken from the STM32G474 reference manual
//! (RM0440 Rev 8: §28.6 TIM1, §21.7 ADC, §42.4 IWDG, §47.16 DBGMCU, §9.1 SYSCFG, §24.6 COMP,
//! §22.7 DAC, §10.4 GPIO) and the drive's design values (firmware/README.md). A field that reads
//! otherwise refuses every arming until reset ([`crate::drive::DriveLoop::set_board_faults`]);
//! the boot log names it. `scripts/fw emulate` asserts an independent copy of the same table on
//! the emulated register image, and that a wrong value refuses arming.
//!
//! The overcurrent comparators (issue 64 item 1) are configured from [`HwTrip`]: thresholds from
//! the software overcurrent limit, the current-sense scaling and a margin.
//!
//! HAL-free: the table is data, the check takes a register reader.

use crate::drive::{dead_time_ticks, PWM_HZ, SYSCLK_HZ};
use gma_control::faults::FaultLimits;
use gma_control::units::Calibration;

/// Register addresses (RM0440 §2.2.2 memory map).
pub mod addr {
    /// TIM1 base.
    pub const TIM1: u32 = 0x4001_2C00;
    /// ADC1 base.
    pub const ADC1: u32 = 0x5000_0000;
    /// IWDG base.
    pub const IWDG: u32 = 0x4000_3000;
    /// DBGMCU base.
    pub const DBGMCU: u32 = 0xE004_2000;
    /// SYSCFG base.
    pub const SYSCFG: u32 = 0x4001_0000;
    /// COMP1_CSR; COMPx_CSR at + 4 (x − 1).
    pub const COMP1: u32 = 0x4001_0200;
    /// DAC1 base.
    pub const DAC1: u32 = 0x5000_0800;
    /// DAC3 base.
    pub const DAC3: u32 = 0x5000_1000;
    /// GPIOA base.
    pub const GPIOA: u32 = 0x4800_0000;
    /// GPIOB base.
    pub const GPIOB: u32 = 0x4800_0400;
}

/// One field group of the expected register image.
#[derive(Clone, Copy, Debug)]
pub struct Expect {
    /// What it is, as the boot log says it.
    pub what: &'static str,
    /// Register address.
    pub addr: u32,
    /// The bits checked.
    pub mask: u32,
    /// Their value.
    pub want: u32,
}

/// The hardware overcurrent trip: COMP3 (INP = PA0, the current amplifier; INM = DAC3 CH1, an
/// internal channel) trips on the positive side, COMP1 (INP = PB1, the threshold DAC1 OUT1 drives
/// on PA4 and a board wire carries to PB1; INM = PA0) on the negative side; both reach TIM1's break
/// through TIM1_AF1.BKCMP3E / BKCMP1E.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HwTrip {
    /// Trip current magnitude [A].
    pub trip_a: f32,
    /// DAC3 CH1 code of the positive threshold (12 bit, right aligned).
    pub positive_code: u16,
    /// DAC1 CH1 code of the negative threshold.
    pub negative_code: u16,
}

/// The hardware trip sits this far above the software overcurrent limit: the firmware's per-tick
/// check trips first on a slow rise, the comparators catch what rises within a tick (a short).
pub const HW_TRIP_MARGIN: f32 = 1.1;

impl HwTrip {
    /// Thresholds for `limits.overcurrent_a` × [`HW_TRIP_MARGIN`] around the nominal current zero
    /// of `cal` (4.4 A: 2.53 V and 0.77 V on the reference board).
    pub fn new(limits: &FaultLimits, cal: &Calibration) -> Self {
        let trip_a = limits.overcurrent_a * HW_TRIP_MARGIN;
        let code = |v: f32| {
            let c = v / cal.vref * 4095.0 + 0.5;
            if c <= 0.0 {
                0
            } else if c >= 4095.0 {
                4095
            } else {
                c as u16
            }
        };
        Self {
            trip_a,
            positive_code: code(cal.current_zero_v + cal.current_v_per_a * trip_a),
            negative_code: code(cal.current_zero_v - cal.current_v_per_a * trip_a),
        }
    }
}

/// COMPx_CSR fields (RM0440 §24.6.1).
pub mod comp {
    /// EN.
    pub const EN: u32 = 1 << 0;
    /// INMSEL = 100: DAC3 CH1 on COMP1 and COMP3 (RM0440 Table 197).
    pub const INM_DAC3_CH1: u32 = 0b100 << 4;
    /// INMSEL = 111: PA0 on COMP1 (RM0440 Table 197).
    pub const INM_PA0: u32 = 0b111 << 4;
    /// INMSEL field.
    pub const INM_MASK: u32 = 0b111 << 4;
    /// INPSEL = 1: PB1 on COMP1; 0: PA0 on COMP3 (RM0440 Table 196).
    pub const INP_1: u32 = 1 << 8;
    /// POL (output inverted).
    pub const POL: u32 = 1 << 15;
    /// HYST = 011: 30 mV (0.15 A of the 0.2 V/A amplifier).
    pub const HYST_30MV: u32 = 0b011 << 16;
    /// HYST field.
    pub const HYST_MASK: u32 = 0b111 << 16;
    /// BLANKSEL field (000: no blanking).
    pub const BLANK_MASK: u32 = 0b111 << 19;
    /// VALUE: the output (read only).
    pub const VALUE: u32 = 1 << 30;
    /// LOCK: the register read-only until reset.
    pub const LOCK: u32 = 1 << 31;
    /// COMP3: positive trip, PA0 against DAC3 CH1.
    pub const COMP3_CSR: u32 = EN | INM_DAC3_CH1 | HYST_30MV;
    /// COMP1: negative trip, PB1 (the low threshold) against PA0.
    pub const COMP1_CSR: u32 = EN | INM_PA0 | INP_1 | HYST_30MV;
}

/// TIM1_AF1 (RM0440 §28.6.26): BKINE (PA6, the gate driver's fault line), BKCMP1E and BKCMP3E,
/// the BKIN polarity as is (BKINP = 0: active low with BKP = 0) and both comparators inverted
/// (BKCMPxP = 1: with BKP = 0, the break is active low, and a comparator output is high on a trip).
pub const TIM1_AF1: u32 = 1 | (1 << 1) | (1 << 3) | (1 << 10) | (1 << 12);

/// Bits of the mismatch mask beyond the table's: the comparator route's self-test at boot.
pub mod route {
    /// COMP3 did not follow its threshold (low threshold → output 1, high → 0) with the bridge off.
    pub const POSITIVE: u32 = 1 << 30;
    /// COMP1 did not follow its threshold on PB1 (the board wire PA4 → PB1 missing?).
    pub const NEGATIVE: u32 = 1 << 31;
    /// CR1.DIR at the conversion interrupt not the expected sampling edge (set by the interrupt).
    pub const SAMPLE_EDGE: u32 = crate::drive::SAMPLE_EDGE_FAULT;
}

/// Number of table entries.
pub const ENTRIES: usize = 27;

/// The register image gma-drive must leave once configured (before the interrupt is unmasked).
pub fn expected(trip: &HwTrip) -> [Expect; ENTRIES] {
    use addr::*;
    // embassy's center-aligned PWM writes ARR = f_timer / (2 f) − 1: the carrier runs at
    // 20.005 kHz and a tick lasts 4 × 4249 = 16 996 cycles (0.02 % short of the 17 000 the tick
    // check expects, well inside its ±2 %).
    let arr = SYSCLK_HZ / (2 * PWM_HZ) - 1;
    let dtg = dead_time_ticks(SYSCLK_HZ);
    let e = |what, addr, mask, want| Expect { what, addr, mask, want };
    [
        e("TIM1_CR1 CEN, CMS = 11 (center-aligned 3)", TIM1, 0x61, 0x61),
        e("TIM1_ARR (20 kHz center-aligned)", TIM1 + 0x2C, 0xFFFF, arr),
        e("TIM1_RCR = 3 (a trigger every 4th half-period)", TIM1 + 0x30, 0xFFFF, 3),
        e("TIM1_CR2 MMS2 = 0010 (TRGO2 = update), OIS1/1N/2/2N = 0", TIM1 + 0x04, (0xF << 20) | (0xF << 8), 0b0010 << 20),
        e("TIM1_BDTR DTG (dead time)", TIM1 + 0x44, 0xFF, dtg),
        e("TIM1_BDTR OSSI = OSSR = 1", TIM1 + 0x44, 0b11 << 10, 0b11 << 10),
        e("TIM1_BDTR BKE = 1, BKP = 0 (active low), AOE = 0", TIM1 + 0x44, 0b111 << 12, 1 << 12),
        e("TIM1_BDTR BKF = 0011 (fCK_INT, N = 8)", TIM1 + 0x44, 0xF << 16, 0b0011 << 16),
        e("TIM1_BDTR BK2E = 0", TIM1 + 0x44, 1 << 24, 0),
        e("TIM1_BDTR LOCK = 11 (level 3)", TIM1 + 0x44, 0b11 << 8, 0b11 << 8),
        e("TIM1_CCER CC1E CC1NE CC2E CC2NE, polarities active high", TIM1 + 0x20, 0xFF, 0x55),
        e(
            "TIM1_CCMR1 OC1M = OC2M = 0110 (PWM mode 1), OC1PE = OC2PE = 1, CCxS = output",
            TIM1 + 0x18,
            (0x1007 << 4) | (0x1007 << 12) | 0x0B0B,
            (0x6 << 4) | (0x6 << 12) | 0x0808,
        ),
        e("TIM1_AF1 BKINE, BKCMP1E, BKCMP3E, BKINP = 0, BKCMP1P = BKCMP3P = 1", TIM1 + 0x60, 0x1FFF, TIM1_AF1),
        e(
            "ADC1_JSQR JL = 2 (3 ranks), JEXTSEL = 01000 (TIM1_TRGO2), JEXTEN = 01 (rising), JSQ1..3 = 1, 2, 6",
            ADC1 + 0x4C,
            0x03FF_FFFF,
            2 | (8 << 2) | (1 << 7) | (1 << 9) | (2 << 15) | (6 << 21),
        ),
        e("ADC1_SMPR1 SMP1 = SMP2 = SMP6 = 011 (24.5 cycles)", ADC1 + 0x14, (7 << 3) | (7 << 6) | (7 << 18), (3 << 3) | (3 << 6) | (3 << 18)),
        e("ADC1_IER JEOSIE", ADC1 + 0x04, 1 << 6, 1 << 6),
        e("ADC1_CR ADEN, JADSTART", ADC1 + 0x08, 0b1001, 0b1001),
        e("IWDG_PR = 000 (/4)", IWDG + 0x04, 0b111, 0),
        e("IWDG_RLR = 15 (16 × 4 / 32 kHz = 2 ms)", IWDG + 0x08, 0xFFF, 15),
        e("DBGMCU_APB2FZR DBG_TIM1_STOP", DBGMCU + 0x10, 1 << 11, 1 << 11),
        e("DBGMCU_APB1FZR1 DBG_IWDG_STOP", DBGMCU + 0x08, 1 << 12, 1 << 12),
        e("SYSCFG_CFGR2 CLL, SPL, ECCL", SYSCFG + 0x1C, 0b1011, 0b1011),
        e(
            "COMP3_CSR EN, INP = PA0, INM = DAC3 CH1, POL = 0, HYST = 30 mV, no blanking, LOCK",
            COMP1 + 8,
            comp::EN | comp::INM_MASK | comp::INP_1 | comp::POL | comp::HYST_MASK | comp::BLANK_MASK | comp::LOCK,
            comp::COMP3_CSR | comp::LOCK,
        ),
        e(
            "COMP1_CSR EN, INP = PB1, INM = PA0, POL = 0, HYST = 30 mV, no blanking, LOCK",
            COMP1,
            comp::EN | comp::INM_MASK | comp::INP_1 | comp::POL | comp::HYST_MASK | comp::BLANK_MASK | comp::LOCK,
            comp::COMP1_CSR | comp::LOCK,
        ),
        e("DAC3_DHR12R1 = the positive trip threshold", DAC3 + 0x08, 0xFFF, trip.positive_code as u32),
        e("DAC1_DHR12R1 = the negative trip threshold", DAC1 + 0x08, 0xFFF, trip.negative_code as u32),
        e(
            "DAC3 EN1, MODE1 = 011 (internal, unbuffered); DAC1 EN1, MODE1 = 000 (pin PA4, buffered); PA0, PA4, PB1 analog",
            DAC3,
            1,
            1,
        ),
    ]
}

/// The checks on top of the table that need two registers (DAC mode registers, the analog pins):
/// folded into the last entry's bit when they fail.
pub fn check_modes(read: &impl Fn(u32) -> u32) -> bool {
    let dac3_mode = read(addr::DAC3 + 0x3C) & 0b111 == 0b011;
    let dac1 = read(addr::DAC1) & 1 != 0 && read(addr::DAC1 + 0x3C) & 0b111 == 0;
    // MODER: PA0 and PA4 analog (11), PB1 analog.
    let pa = read(addr::GPIOA) & ((0b11 << 0) | (0b11 << 8)) == (0b11 << 0) | (0b11 << 8);
    let pb = read(addr::GPIOB) & (0b11 << 2) == 0b11 << 2;
    dac3_mode && dac1 && pa && pb
}

/// Compares the register image `read` gives with [`expected`]: bit k of the result set for
/// each entry k that differs (0: all as the table says).
pub fn check(table: &[Expect; ENTRIES], read: impl Fn(u32) -> u32) -> u32 {
    let mut bad = 0u32;
    for (k, e) in table.iter().enumerate() {
        if read(e.addr) & e.mask != e.want {
            bad |= 1 << k;
        }
    }
    if !check_modes(&read) {
        bad |= 1 << (ENTRIES - 1);
    }
    bad
}

const _: () = assert!(ENTRIES <= 29, "the route and edge bits sit above the table's");
