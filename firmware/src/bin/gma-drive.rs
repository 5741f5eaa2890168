//! Drive firmware for an STM32G474RE board (NUCLEO-G474RE class), see firmware/README.md for
//! the pinout, scaling and timing. The hardware glue only: TIM1 center-aligned complementary PWM
//! at 20 kHz drives the full bridge, with the gate driver's fault pin on its break input; its
//! update event (every 4th half-period: 10 kHz) triggers the ADC's injected conversion of coil
//! current, displacement and bus voltage; the end-of-conversion interrupt (highest priority) runs
//! `firmware::drive` — one `gma_control` tick, the same code the host and QEMU tests run — which
//! sets the bridge, feeds the watchdog, checks the deadline and queues the raw telemetry record.
//! Thread mode encodes the records and sends them by DMA over USART2 (the ST-LINK virtual COM
//! port, 4 Mbaud), and receives command bytes by DMA into a ring buffer.
//!
//! Safe state: MOE off, every gate low (OSSI = OSSR = 1, idle levels 0). It holds from before the
//! channels are enabled, on any latched fault, on a break-input trip (hardware, in the same PWM
//! cycle; MOE is written 1 only on the arming tick, never over a break flag), in the panic and
//! HardFault handlers (interrupts off, so nothing sets MOE again or feeds the watchdog; a stack
//! overflow faults below SRAM and the HardFault entry resets the stack pointer first,
//! `firmware::fault`), on a core lockup, an SRAM parity error or a flash ECC error (system break
//! inputs, hardware), while a debugger halts the core (TIM1 frozen), and after a watchdog reset.
#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m::peripheral::NVIC;
use critical_section::Mutex;
use defmt::{error, info, warn};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, InjectedAdc, SampleTime};
use embassy_stm32::gpio::{AfType, Flex, OutputType, Pull};
use embassy_stm32::interrupt::Priority;
use embassy_stm32::pac::iwdg::vals::Key;
use embassy_stm32::peripherals::{ADC1, IWDG, TIM1};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{
    BreakInputPolarity, ComplementaryPwm, ComplementaryPwmPin, FilterValue, Mms2, Ossi, Ossr,
};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{BkIn1, BreakInputPin, Channel};
use embassy_stm32::usart::{self, Config as UartConfig, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, interrupt, pac, peripherals, Config};
use embassy_time::{with_timeout, Duration, Instant, Timer};
use firmware::board_check::{self, HwTrip};
use firmware::drive::{
    boot_config, dead_time_ticks, encode_queued, encode_replies, execute, quiet_window_max_duty,
    BridgeTiming, CommandPort, DriveCounters, DriveLoop, PowerStage, ReplyQueue, Slot, TelemetryQueue,
    PWM_HZ, SYSCLK_HZ, TELEMETRY_QUEUE, TICK_CYCLES,
};
use firmware::drive_params::{MODEL_SPEC, PARAMS_POSTCARD, PARAMS_SOURCE};
use gma_control::command::{Reply, MAX_REPLY_ENCODED};
use gma_control::crash::{Crash, CrashRecord};
use gma_control::telemetry::{TimedFrame, MAX_ENCODED};
use gma_control::watchdog::participants::{COMMAND_TASK, CONTROL_ISR, TELEMETRY_TASK};
use gma_control::watchdog::{participants, CheckIn};
use gma_control::{Controller, ResetCause};
use heapless::spsc::{Consumer, Producer};
use {defmt_rtt as _, embassy_stm32 as _};

bind_interrupts!(struct Irqs {
    USART2 => usart::InterruptHandler<peripherals::USART2>;
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    DMA1_CHANNEL2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
});

/// The interrupt's state (controller, bridge, telemetry producer) in CCM SRAM: zero-wait-state,
/// off the DMA's bus, and written at start-up (no initial value in flash, see `Slot`).
#[allow(unsafe_code)] // link_section: `.ccmram` is NOLOAD in memory.x and `Slot` needs no initial value.
#[link_section = ".ccmram"]
static DRIVE_STATE: Slot<DriveLoop<BoardStage>> = Slot::new();
/// The interrupt's handle on `DRIVE_STATE` (None until start-up has written it).
static DRIVE: Mutex<RefCell<Option<&'static mut DriveLoop<BoardStage>>>> = Mutex::new(RefCell::new(None));
/// Telemetry records from the interrupt to thread mode.
static TELEMETRY: Slot<TelemetryQueue> = Slot::new();
/// What the interrupt publishes for the status log.
static COUNTERS: DriveCounters = DriveCounters::new();
/// UART RX ring for command bytes (DMA, circular).
static COMMAND_RING: Slot<[u8; 256]> = Slot::new();
/// Command replies from the command task to the UART writer.
static REPLIES: Slot<ReplyQueue> = Slot::new();
/// The check-ins of the interrupt and the two thread-mode tasks (`gma_control::watchdog`): the
/// interrupt feeds the watchdog only while all come, within [`CHECK_IN_WINDOW_TICKS`].
static CHECK_IN: CheckIn = CheckIn::new(&participants::ALL);
/// How long the interrupt goes on feeding the 2 ms watchdog without a complete round of
/// check-ins [ticks]: 100 ms. `CheckIn::take_if_all` consumes the check-ins on each complete
/// round, so without a window the watchdog would be fed only as often as the slowest task
/// checks in: the command task, idle, every [`COMMAND_IDLE_CHECKIN_MS`] (20 ms), and busy for
/// ≈ 2.5 ms building a parameter load's model outside the critical section — either resets a
/// healthy board through the 2 ms watchdog. 100 ms is five idle command check-ins; a task silent
/// for longer is hung: the bridge goes off at once and the watchdog resets the board 2 ms later.
const CHECK_IN_WINDOW_TICKS: u32 = 1000;
/// The command task's check-in period while no byte arrives [ms] (its read's timeout).
const COMMAND_IDLE_CHECKIN_MS: u64 = 20;
/// Replies the command task had no queue room for (its `CommandPort::replies_dropped`).
static REPLIES_DROPPED: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
/// The board check's mismatches, for the status log.
static BOARD_FAULTS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

/// The counter direction TIM1 must show in the conversion interrupt: counting up, just past the
/// trough. After the software update event that follows the RCR write, the repetition counter
/// (3) lets every 4th extreme through and the counter started at 0, so each update is an
/// underflow (RM0440 §28.3.3, "Repetition counter"). The quiet window around the sample is the
/// same at a peak, but a trigger moved to the other extreme means the timer's phase is not the
/// one the firmware set: refused.
const SAMPLE_DIR: pac::timer::vals::Dir = pac::timer::vals::Dir::UP;

/// Encoded telemetry per DMA transfer: up to 8 frames (0.6 ms of UART time at 4 Mbaud), after
/// the replies waiting then.
const TX_BATCH: usize = 8 * MAX_ENCODED + firmware::drive::REPLY_QUEUE * MAX_REPLY_ENCODED;

/// Clears MOE straight in TIM1's BDTR: works with nothing else initialised (panic, HardFault).
fn bridge_off() {
    pac::TIM1.bdtr().modify(|w| w.set_moe(false));
}

/// Starts the independent watchdog (key 0xCCCC in IWDG_KR, RM0440 "IWDG key register"; a no-op
/// when it runs already): a fault before start-up unleashed it still ends in a reset, with
/// the reset-default timeout (about 512 ms) if start-up had not configured it yet.
fn watchdog_start() {
    pac::IWDG.kr().write(|w| w.set_key(Key::START));
}

/// NMI (RM0440: the clock security system, SRAM parity and flash ECC errors can raise it): the
/// bridge off at once and left to the watchdog, as in the panic handler; never returns, so no
/// unexpected source can keep the bridge switching.
#[allow(unsafe_code)] // cortex-m-rt requires an NMI handler to be an `unsafe fn`.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() -> ! {
    cortex_m::interrupt::disable();
    bridge_off();
    watchdog_start();
    loop {
        cortex_m::asm::nop();
    }
}

/// Any interrupt or exception without a handler of its own (cortex-m-rt's default looped with
/// the bridge switching at its last duty until the watchdog reset): bridge off, then the watchdog.
#[allow(unsafe_code)] // cortex-m-rt's DefaultHandler must be an `unsafe fn`.
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(_irqn: i16) -> ! {
    cortex_m::interrupt::disable();
    bridge_off();
    watchdog_start();
    loop {
        cortex_m::asm::nop();
    }
}

/// One 32-bit register read at `addr`, for the board check's table.
#[allow(unsafe_code)]
fn read_register(addr: u32) -> u32 {
    // SAFETY: called only with the addresses of `board_check::expected` and `check_modes`:
    // registers of this part (RM0440 memory map) whose peripherals are clocked by then, and
    // none of which changes state on a read (no FIFO, no clear-on-read flag).
    unsafe { core::ptr::read_volatile(addr as *const u32) }
}

/// The overcurrent comparators (firmware::board_check::HwTrip): DAC thresholds, the comparators,
/// and a self-test with the bridge off before they are routed to the break: each must follow its
/// DAC to both sides of the current amplifier's zero (PA0 ≈ 1.65 V), so that a missing board wire
/// or a wrong input selection is measured, not assumed. Returns the route bits of a failed test.
fn overcurrent_comparators(trip: &HwTrip) -> u32 {
    use board_check::{comp, route};
    use embassy_stm32::pac::comp::regs::Csr;
    use embassy_stm32::pac::gpio::vals::Moder;
    pac::RCC.ahb2enr().modify(|w| {
        w.set_dac1en(true);
        w.set_dac3en(true);
        w.set_gpioaen(true);
        w.set_gpioben(true);
    });
    pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    // PA4 (DAC1 OUT1) and PB1 (COMP1 INP) analog; PA0 is the ADC's already.
    pac::GPIOA.moder().modify(|w| {
        w.set_moder(0, Moder::ANALOG);
        w.set_moder(4, Moder::ANALOG);
    });
    pac::GPIOB.moder().modify(|w| w.set_moder(1, Moder::ANALOG));
    // DAC_MCR (RM0440 §22.7.16): HFSEL = 10 (AHB clock above 160 MHz); DAC3 CH1 MODE = 011
    // (on-chip peripherals only, no buffer), DAC1 CH1 MODE = 000 (its pin, buffered).
    pac::DAC3.mcr().modify(|w| w.0 = (w.0 & !((0b11 << 14) | 0b111)) | (0b10 << 14) | 0b011);
    pac::DAC1.mcr().modify(|w| w.0 = (w.0 & !((0b11 << 14) | 0b111)) | (0b10 << 14));
    let set = |positive: u16, negative: u16| {
        pac::DAC3.dhr12r(0).write(|w| w.0 = positive as u32);
        pac::DAC1.dhr12r(0).write(|w| w.0 = negative as u32);
        // DAC settling (buffered, ≤ 3 µs) and the comparator's propagation: 20 µs.
        cortex_m::asm::delay(SYSCLK_HZ / 50_000);
    };
    pac::DAC3.cr().modify(|w| w.0 |= 1);
    pac::DAC1.cr().modify(|w| w.0 |= 1);
    // DACxRDY (DAC_SR bit 11), bounded.
    for _ in 0..10_000 {
        if pac::DAC3.sr().read().0 & pac::DAC1.sr().read().0 & (1 << 11) != 0 {
            break;
        }
    }
    pac::COMP3.csr().write_value(Csr(comp::COMP3_CSR));
    pac::COMP1.csr().write_value(Csr(comp::COMP1_CSR));
    let out3 = || pac::COMP3.csr().read().0 & comp::VALUE != 0;
    let out1 = || pac::COMP1.csr().read().0 & comp::VALUE != 0;
    let mut faults = 0;
    // COMP3 high when PA0 > DAC3; COMP1 high when PB1 (DAC1) > PA0.
    set(0, 4095);
    let (p_low, n_high) = (out3(), out1());
    set(4095, 0);
    let (p_high, n_low) = (out3(), out1());
    set(trip.positive_code, trip.negative_code);
    let (p_idle, n_idle) = (out3(), out1());
    if !(p_low && !p_high && !p_idle) {
        faults |= route::POSITIVE;
    }
    if !(n_high && !n_low && !n_idle) {
        faults |= route::NEGATIVE;
    }
    // Read-only until reset (COMPx_CSR.LOCK).
    pac::COMP3.csr().write_value(Csr(comp::COMP3_CSR | comp::LOCK));
    pac::COMP1.csr().write_value(Csr(comp::COMP1_CSR | comp::LOCK));
    faults
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Interrupts off first: the 10 kHz interrupt would otherwise run on, set MOE again while
    // armed and feed the watchdog. Never re-enabled: the watchdog resets the board into its
    // idle boot, which sees the watchdog reset.
    cortex_m::interrupt::disable();
    bridge_off();
    watchdog_start();
    let crash = match info.location() {
        Some(at) => Crash::panic_at(at.file(), at.line(), at.column()),
        None => Crash::panic_at("", 0, 0),
    };
    crash_words::store(&CrashRecord::encode_new(crash));
    error!("gma-drive: panic: {}", defmt::Display2Format(info));
    loop {
        cortex_m::asm::nop();
    }
}

/// Called by `firmware::fault`'s HardFault entry with the stack pointer reset, so that it runs
/// even after a stack overflow; the watchdog, no longer fed, then resets the board.
#[allow(unsafe_code)] // no_mangle: the symbol the HardFault entry branches to.
#[no_mangle]
extern "C" fn gma_hard_fault() -> ! {
    // HardFault already blocks the interrupt; disabled anyway, as in the panic handler.
    cortex_m::interrupt::disable();
    bridge_off();
    watchdog_start();
    let status = firmware::fault::FaultStatus::read();
    crash_words::store(&CrashRecord::encode_new(Crash::HardFault {
        cfsr: status.cfsr,
        hfsr: status.hfsr,
        bus_fault_address: status.bus_fault_address,
        // One frame of the deepest call chain lands within 1 KiB below the floor.
        stack_overflow: status.is_stack_overflow(1024),
    }));
    loop {
        cortex_m::asm::nop();
    }
}

/// Where a crash is kept across the watchdog reset that follows it (`gma_control::crash`): the
/// TAMP backup registers BKP0R–BKP7R (RM0440 "TAMP backup registers"), which a system reset
/// leaves alone and a power cycle or a backup-domain reset clears. Register interface only: no
/// HAL state, so that the panic and HardFault handlers can use it with nothing initialised.
mod crash_words {
    use embassy_stm32::pac;
    use gma_control::crash::CRASH_WORDS;

    /// Clocks PWR and the RTC/TAMP register interface (RCC_APB1ENR1.PWREN, RTCAPBEN) and lifts
    /// the backup domain's write protection (PWR_CR1.DBP).
    fn unlock() {
        pac::RCC.apb1enr1().modify(|w| {
            w.set_pwren(true);
            w.set_rtcapben(true);
        });
        pac::PWR.cr1().modify(|w| w.set_dbp(true));
        // DBP takes effect a few cycles later; bounded, as a handler must not hang here.
        for _ in 0..1000 {
            if pac::PWR.cr1().read().dbp() {
                break;
            }
        }
    }

    /// The words as the last run left them.
    pub fn load() -> [u32; CRASH_WORDS] {
        unlock();
        core::array::from_fn(|i| pac::TAMP.bkpr(i).read().bkp())
    }

    /// Writes the words, first to last.
    pub fn store(words: &[u32; CRASH_WORDS]) {
        unlock();
        for (i, &w) in words.iter().enumerate() {
            pac::TAMP.bkpr(i).write(|r| r.set_bkp(w));
        }
    }
}

// SRAM parity (RM0440 "Embedded SRAM", and FLASH_OPTR in "FLASH option register"): with the
// SRAM_PE option bit at 0 (parity ON — the bit disables it; the G4 HAL's OB_SRAM_PARITY_ENABLE
// is 0, covering CCM SRAM and the start of SRAM1) every read of a byte never written since
// power-on can raise a parity error, which SYSCFG_CFGR2.SPL turns into a TIM1 system break
// and an NMI. Moves of structs read their padding, and `.ccmram` is NOLOAD; so before any RAM
// initialisation (cortex-m-rt's `__pre_init`, no stack in use yet) all of CCM SRAM and SRAM1 are
// zeroed when parity is on. Plain assembly: no Rust code may run before RAM is initialised.
// SAFETY: runs once from the reset handler before `.bss`/`.data` are set up; touches only
// FLASH_OPTR (read) and the parity-checked RAM, which holds nothing yet.
#[allow(unsafe_code)]
mod pre_init {
    core::arch::global_asm!(
        ".section .text.__pre_init, \"ax\", %progbits",
        ".global __pre_init",
        ".type __pre_init, %function",
        ".thumb_func",
        "__pre_init:",
        "    ldr r0, =0x40022020", // FLASH_OPTR
        "    ldr r0, [r0]",
        "    tst r0, #0x01000000", // SRAM_PE = 1: parity off, nothing to do
        "    bne 3f",
        "    movs r2, #0",
        "    ldr r0, =0x10000000", // CCM SRAM, 32 KiB
        "    ldr r1, =0x10008000",
        "1:  str r2, [r0], #4",
        "    cmp r0, r1",
        "    bne 1b",
        "    ldr r0, =0x20000000", // SRAM1, 80 KiB (the stack is empty: nothing has run)
        "    ldr r1, =0x20014000",
        "2:  str r2, [r0], #4",
        "    cmp r0, r1",
        "    bne 2b",
        "3:  bx lr",
        "    .ltorg",
    );
}

/// The board's side of the interrupt: register accesses through the PAC, the HAL drivers kept
/// alive so that their drops never stop the timer or the ADC.
struct BoardStage {
    _pwm: ComplementaryPwm<'static, TIM1>,
    _adc: InjectedAdc<'static, ADC1, 3>,
    _break_pin: Flex<'static>,
    watchdog: IndependentWatchdog<'static, IWDG>,
    /// Ticks since the last complete round of check-ins (`CHECK_IN.take_if_all`).
    stale_ticks: u32,
}

impl PowerStage for BoardStage {
    fn read_conversions(&mut self) -> [u16; 3] {
        let adc = pac::ADC1;
        let codes = [adc.jdr(0).read().jdata(), adc.jdr(1).read().jdata(), adc.jdr(2).read().jdata()];
        // Write-one-to-clear: only JEOS, so that the deadline check sees the next one.
        adc.isr().write(|w| w.set_jeos(true));
        codes
    }

    fn take_break_flags(&mut self) -> bool {
        // TIM1_SR (RM0440 Rev 4 §28.6.5): BIF (break input 1, the gate driver), B2IF (break
        // input 2) and SBIF (system break: lockup, SRAM parity, flash ECC via SYSCFG_CFGR2).
        let sr = pac::TIM1.sr().read();
        let tripped = sr.bif(0) || sr.bif(1) || sr.sbif();
        if tripped {
            // rc_w0: writing 0 clears a flag (not while its source is still active), 1 leaves
            // the other flags alone.
            pac::TIM1.sr().write(|w| {
                w.0 = !0;
                w.set_bif(0, false);
                w.set_bif(1, false);
                w.set_sbif(false);
            });
        }
        tripped
    }

    fn break_pending(&self) -> bool {
        let sr = pac::TIM1.sr().read();
        sr.bif(0) || sr.bif(1) || sr.sbif()
    }

    fn set_compare(&mut self, leg_a: u16, leg_b: u16) {
        pac::TIM1.ccr(0).write(|w| w.set_ccr(leg_a));
        pac::TIM1.ccr(1).write(|w| w.set_ccr(leg_b));
    }

    fn set_outputs_enabled(&mut self, enabled: bool) {
        // TIM1_BDTR.MOE (RM0440 Rev 4 §28.6.20): cleared asynchronously by any break; it cannot
        // be set while a break source is active. `firmware::drive` writes 1 only on the arming
        // tick, after checking the flags.
        pac::TIM1.bdtr().modify(|w| w.set_moe(enabled));
    }

    fn outputs_enabled(&self) -> bool {
        // Read on the ticks after the arming one (a read right after writing 1 would see the
        // resynchronised value late, RM0440 §28.3 "Using the break function").
        pac::TIM1.bdtr().read().moe()
    }

    fn feed_watchdog(&mut self) {
        // Only while every participant checks in (gma_control::watchdog): the interrupt here,
        // the command and telemetry tasks in thread mode, each round within the window; a hung
        // task turns the bridge off now and the watchdog resets the board within its 2 ms.
        CHECK_IN.check_in(CONTROL_ISR);
        if CHECK_IN.take_if_all() {
            self.stale_ticks = 0;
        } else {
            self.stale_ticks = self.stale_ticks.saturating_add(1);
        }
        if self.stale_ticks <= CHECK_IN_WINDOW_TICKS {
            self.watchdog.pet();
        } else {
            bridge_off();
        }
    }

    fn sample_edge_ok(&self) -> bool {
        pac::TIM1.cr1().read().dir() == SAMPLE_DIR
    }

    fn next_conversion_done(&self) -> bool {
        pac::ADC1.isr().read().jeos()
    }

    fn cycle_count(&self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }
}

fn clocks() -> Config {
    use embassy_stm32::rcc::{mux, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
    let mut config = Config::default();
    // HSI 16 MHz / 4 × 85 / 2 = 170 MHz SYSCLK (boost mode needed above 150 MHz).
    config.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = true;
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    // UART DMA below the 10 kHz interrupt (priority 0).
    config.bdma_interrupt_priority = Priority::P2;
    config
}

/// The reset cause from RCC_CSR, whose flags are then cleared so that the next boot reads its
/// own.
fn take_reset_cause() -> ResetCause {
    let csr = pac::RCC.csr().read();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    ResetCause::from_rcc_flags(
        csr.iwdgrstf(),
        csr.wwdgrstf(),
        csr.sftrstf(),
        csr.borrstf(),
        csr.pinrstf(),
        csr.lpwrrstf(),
    )
}

/// The controller for the compiled-in parameter set (`GMA_PARAMS`, `GMA_MODEL` at build time);
/// a set that does not decode or validate leaves the bridge off with PARAMETERS_INVALID; a
/// watchdog reset boots with WATCHDOG_RESET latched.
fn controller(reset: ResetCause) -> Controller {
    let spec = model_core::ModelSpec::parse(MODEL_SPEC);
    let params = postcard::from_bytes::<model_core::ActuatorParams>(PARAMS_POSTCARD);
    match (spec, params) {
        (Ok(spec), Ok(params)) => Controller::new(boot_config(), spec, &params, reset),
        _ => Controller::refused(boot_config(), reset),
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Paint the free stack first, so that the status log can report how deep it has reached.
    firmware::stack::paint();
    // Frozen while a debugger halts the core: TIM1 (a halted loop must not keep switching) and
    // the watchdog (halting is not a fault).
    pac::DBGMCU.apb2fzr().modify(|w| w.set_tim1(true));
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
    let reset_cause = take_reset_cause();
    // Before the HAL's clock set-up: it resets the backup domain when the RTC clock settings there
    // are not its own (after a power cycle, when the words hold nothing anyway).
    let last_crash = CrashRecord::decode(&crash_words::load());
    if let Some(record) = last_crash {
        crash_words::store(&record.aged());
    }
    let p = embassy_stm32::init(clocks());
    // System break sources on TIM1's break input, in hardware (RM0440 §9.1.2 SYSCFG_CFGR2;
    // set-once bits, cleared only by reset): a core lockup (a fault the HardFault handler could
    // not take), a parity error in CCM SRAM (where the control state lives) and a double ECC
    // error in flash each clear MOE with no code running. Set before TIM1 is configured, so
    // the bridge is never enabled without them. (embassy_stm32::init enabled SYSCFG's clock.)
    pac::SYSCFG.cfgr2().modify(|w| {
        w.set_cll(true);
        w.set_spl(true);
        w.set_eccl(true);
    });
    info!(
        "gma-drive: SYSCLK 170 MHz, model `{}` with {}, reset by {}",
        MODEL_SPEC,
        PARAMS_SOURCE,
        defmt::Debug2Format(&reset_cause)
    );
    if let Some(record) = last_crash {
        warn!("gma-drive: {}", defmt::Display2Format(&record));
    }
    // FLASH_OPTR.SRAM_PE (RM0440 "FLASH option register"; 0 = parity checked): whether SYSCFG_CFGR2.SPL above
    // guards anything. When it is on, `__pre_init` zeroed CCM SRAM and SRAM1 at reset.
    if pac::FLASH.optr().read().sram_pe() {
        warn!("gma-drive: SRAM parity check OFF (FLASH_OPTR.SRAM_PE = 1): a CCM SRAM bit error goes unseen");
    } else {
        info!("gma-drive: SRAM parity check on (FLASH_OPTR.SRAM_PE = 0); CCM SRAM and SRAM1 zeroed at reset");
    }

    // Full bridge: TIM1 CH1/CH1N (PA8/PA7) one leg, CH2/CH2N (PA9/PB0) the other. The driver
    // sets MOE on construction, before any channel is enabled; it is cleared at once.
    let mut pwm = ComplementaryPwm::new(
        p.TIM1,
        Some(PwmPin::new(p.PA8, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PA7, OutputType::PushPull)),
        Some(PwmPin::new(p.PA9, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB0, OutputType::PushPull)),
        None,
        None,
        None,
        None,
        Hertz::hz(PWM_HZ),
        CountingMode::CenterAlignedBothInterrupts,
    );
    pwm.set_master_output_enable(false);
    // Off state: with MOE off (OSSI) and with a channel disabled while MOE is on (OSSR) the timer
    // drives the pins to their idle levels instead of releasing them; idle level 0 on all four
    // outputs = every gate low. All off rather than both low sides on: the break input means a
    // gate-driver fault (desaturation, short), where switching any transistor on can feed the
    // fault. The coil's energy (48 mJ at 4 A) then returns through the body diodes into the
    // 100 µF bus: 39.2 V from 4 A, 41.7 V from 4.4 A, over the 34 V trip (which latches with
    // every such trip). The divider reads it; the board must absorb it (firmware/README.md,
    // "The coil's energy on a trip").
    pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
    pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
    pac::TIM1.cr2().modify(|w| {
        for ch in 0..2 {
            w.set_ois(ch, false);
            w.set_oisn(ch, false);
        }
    });
    // Break input 1 from the gate driver's open-drain fault output on PA6 (low = fault), pulled
    // up, 8-sample filter against switching noise; no automatic re-enable (AOE = 0).
    let bkin_af = BreakInputPin::<TIM1, BkIn1>::af_num(&*p.PA6);
    let mut break_pin = Flex::new(p.PA6);
    break_pin.set_as_af_unchecked(bkin_af, AfType::input(Pull::Up));
    pwm.set_break_polarity(BreakInputPolarity::ACTIVE_LOW);
    pwm.set_break_filter(FilterValue::FCK_INT_N8);
    pwm.set_break_input_pin_enable(true);
    pwm.set_automatic_output_enable(false);
    pwm.set_break_enable(true);

    pwm.set_repetition_counter(3);
    // A software update event (TIM1_EGR.UG): the counter restarts at 0 and the repetition
    // counter takes 3 now, not at whichever extreme came next after the write, so every update
    // (the ADC trigger) is an underflow; the interrupt checks the edge (CR1.DIR). Before MMS2
    // routes updates to TRGO2 and before the ADC listens: no conversion starts from it.
    pac::TIM1.egr().write(|w| w.set_ug(true));
    pwm.set_mms2(Mms2::UPDATE);
    let period_ticks = pwm.get_max_duty();
    // Center-aligned: the counter runs up and down once per PWM period, so the timer clock is
    // 2 × ARR × f_PWM.
    let timer_hz = 2 * period_ticks * PWM_HZ;
    pwm.set_dead_time(dead_time_ticks(timer_hz) as u16);
    let half = period_ticks / 2;
    pwm.set_duty(Channel::Ch1, half);
    pwm.set_duty(Channel::Ch2, half);
    pwm.enable(Channel::Ch1);
    pwm.enable(Channel::Ch2);
    // The hardware overcurrent trip: the comparators, self-tested, then routed to the break
    // (TIM1_AF1, RM0440 §28.6.26) next to BKIN, before the lock below.
    let hw_trip = HwTrip::new(&boot_config().limits, &boot_config().calibration);
    let route_faults = overcurrent_comparators(&hw_trip);
    pac::TIM1.af1().modify(|w| w.0 = (w.0 & !0x1FFF) | board_check::TIM1_AF1);
    // Lock level 3 (TIM1_BDTR.LOCK, RM0440 Rev 4 §28.6.20; writable once per reset): dead time,
    // break configuration, idle levels, OSSI/OSSR, output polarities and the output compare
    // modes (OCxM, OCxPE) can no longer change until reset — a stray write cannot undo the safe
    // state or turn a PWM channel into a forced-active output. Nothing writes them after this
    // line: the interrupt writes only CCR1/CCR2 and MOE (`BoardStage`), which stay writable.
    pac::TIM1.bdtr().modify(|w| w.set_lock(pac::timer::vals::Lock::LEVEL3));
    let timing = BridgeTiming { period_ticks: period_ticks as u16, max_duty: quiet_window_max_duty() };
    info!(
        "gma-drive: PWM ARR {} at {} Hz timer clock, dead time {} ticks, duty within ±{}",
        period_ticks,
        timer_hz,
        dead_time_ticks(timer_hz),
        timing.max_duty
    );

    // ADC1 injected sequence on TIM1 TRGO2: IN1 (PA0) coil current shunt amplifier first (the
    // quiet window is computed for it), IN2 (PA1) displacement probe, IN6 (PC0) bus divider.
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let injected = adc.setup_injected_conversions(
        [
            (p.PA0.degrade_adc(), SampleTime::CYCLES24_5),
            (p.PA1.degrade_adc(), SampleTime::CYCLES24_5),
            (p.PC0.degrade_adc(), SampleTime::CYCLES24_5),
        ],
        embassy_stm32::triggers::TIM1_TRGO2,
        Exten::RISING_EDGE,
        true,
    );

    // Watchdog: 2 ms, fed by every control tick — a stalled loop resets the board (PWM off).
    // Configured here, started only once the controller exists, right before the interrupt
    // is unmasked: a Preisach model takes about 400 000 instructions (> 2 ms) to build.
    let watchdog = IndependentWatchdog::new(p.IWDG, 2_000);

    let mut uart_config = UartConfig::default();
    uart_config.baudrate = 4_000_000;
    let uart = match Uart::new(p.USART2, p.PA3, p.PA2, p.DMA1_CH1, p.DMA1_CH2, Irqs, uart_config) {
        Ok(u) => u,
        Err(_) => defmt::panic!("USART2 configuration refused"),
    };
    let (tx, rx) = uart.split();
    // SAFETY: the only write to COMMAND_RING.
    #[allow(unsafe_code)]
    let ring = unsafe { COMMAND_RING.write([0; 256]) };
    let rx = rx.into_ring_buffered(ring);

    let controller = controller(reset_cause);
    if !controller.faults().is_clear() {
        warn!("gma-drive: booted with faults latched {:#x}; bridge off until cleared", controller.faults().0);
    }
    // SAFETY: the only write to REPLIES.
    #[allow(unsafe_code)]
    let (reply_producer, reply_consumer) = unsafe { REPLIES.write(ReplyQueue::new()) }.split();
    // SAFETY: the only write to TELEMETRY.
    #[allow(unsafe_code)]
    let (producer, consumer) = unsafe { TELEMETRY.write(TelemetryQueue::new()) }.split();
    // The board checks its own configuration (firmware::board_check): every field the drive's
    // safety rests on, read back against the reference manual's table; a mismatch refuses
    // arming until reset (`parameters_invalid` latched on every tick) and is logged here.
    let table = board_check::expected(&hw_trip);
    let mismatches = board_check::check(&table, read_register) | route_faults;
    for (k, e) in table.iter().enumerate() {
        if mismatches & (1 << k) != 0 {
            let got = read_register(e.addr) & e.mask;
            error!("gma-drive: board check: {} reads {:#x}, want {:#x}: arming refused", e.what, got, e.want);
        }
    }
    if route_faults & board_check::route::POSITIVE != 0 {
        error!("gma-drive: board check: COMP3 (PA0 against DAC3 CH1) does not follow its threshold: arming refused");
    }
    if route_faults & board_check::route::NEGATIVE != 0 {
        error!("gma-drive: board check: COMP1 (PB1 against PA0) does not follow DAC1 OUT1: is PA4 wired to PB1? Arming refused");
    }
    if mismatches == 0 {
        info!(
            "gma-drive: board check: {} register fields as RM0440's table; overcurrent comparators at ±{} A (DAC codes {}, {})",
            board_check::ENTRIES,
            hw_trip.trip_a,
            hw_trip.positive_code,
            hw_trip.negative_code
        );
    }
    BOARD_FAULTS.store(mismatches, core::sync::atomic::Ordering::Relaxed);
    let stage = BoardStage { _pwm: pwm, _adc: injected, _break_pin: break_pin, watchdog, stale_ticks: 0 };
    // SAFETY: the only write to DRIVE_STATE; `.ccmram` is NOLOAD, and this write initialises it.
    #[allow(unsafe_code)]
    let drive = unsafe { DRIVE_STATE.write(DriveLoop::new(controller, stage, timing, producer, &COUNTERS)) };
    drive.set_board_faults(mismatches);
    critical_section::with(|cs| DRIVE.borrow(cs).replace(Some(drive)));

    #[allow(unsafe_code)]
    // SAFETY: the handler only touches the drive through the critical-section mutex, set
    // above; the ADC interrupt gets the highest priority (0), above the UART and its DMA.
    unsafe {
        let mut core = cortex_m::Peripherals::steal();
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();
        core.NVIC.set_priority(pac::Interrupt::ADC1_2, 0);
        core.NVIC.set_priority(pac::Interrupt::USART2, 2 << 4);
        // Everything slow is done: from here every tick feeds it within 2 ms.
        watchdog_start();
        // The conversions have run since the ADC was set up: the flag of the last one is stale
        // (its entry would come at any counter position). The first entry is a fresh one.
        pac::ADC1.isr().write(|w| {
            w.set_jeos(true);
            w.set_jeoc(true);
        });
        NVIC::unpend(pac::Interrupt::ADC1_2);
        NVIC::unmask(pac::Interrupt::ADC1_2);
    }
    info!("gma-drive: watchdog running, tick period checked at {} cycles ± 2 % over 32 ticks", TICK_CYCLES);

    match command_rx(rx, reply_producer) {
        Ok(task) => spawner.spawn(task),
        Err(_) => defmt::panic!("command task not spawned"),
    }
    telemetry_tx(tx, consumer, reply_consumer).await
}

/// Thread mode: sends the waiting command replies, then encodes the queued records (format 2,
/// CRC-16 + COBS), by DMA; logs the drive's counters once a second when something is wrong,
/// and the stack's high-water mark whenever it has grown.
async fn telemetry_tx(
    mut tx: UartTx<'static, embassy_stm32::mode::Async>,
    mut queue: Consumer<'static, TimedFrame>,
    mut replies: Consumer<'static, Reply>,
) -> ! {
    let mut batch = [0u8; TX_BATCH];
    let mut last_report = Instant::now();
    let mut reported = (0u32, 0u32, 0u32, 0u32, 0u32);
    let mut stack_logged = 0;
    loop {
        CHECK_IN.check_in(TELEMETRY_TASK);
        let n = encode_replies(&mut replies, &mut batch);
        let n = n + encode_queued(&mut queue, &mut batch[n..]);
        if n > 0 {
            if tx.write(&batch[..n]).await.is_err() {
                warn!("gma-drive: telemetry UART error");
            }
        } else {
            Timer::after_micros(100).await;
        }
        if last_report.elapsed().as_secs() >= 1 {
            last_report = Instant::now();
            let stack_peak = firmware::stack::peak();
            if stack_peak > stack_logged {
                stack_logged = stack_peak;
                info!("gma-drive: stack peak {} B of {} B", stack_peak, firmware::stack::size());
            }
            let load = |c: &core::sync::atomic::AtomicU32| c.load(core::sync::atomic::Ordering::Relaxed);
            let (dropped, late, trips, off, replies_dropped) = (
                load(&COUNTERS.telemetry_dropped),
                load(&COUNTERS.deadline_overruns),
                load(&COUNTERS.trips),
                load(&COUNTERS.period_off),
                load(&REPLIES_DROPPED),
            );
            // The counters are totals since boot: said when one has grown, not every second.
            if (dropped, late, trips, off, replies_dropped) != reported {
                reported = (dropped, late, trips, off, replies_dropped);
                warn!(
                    "gma-drive: telemetry dropped {} of {}, command replies dropped {}, deadline overruns {}, trips {:#x}, \
                     board check {:#x}, longest tick {} cycles, single tick intervals off ±2 % {} (last 32-tick window {} cycles)",
                    dropped,
                    TELEMETRY_QUEUE,
                    replies_dropped,
                    late,
                    trips,
                    load(&BOARD_FAULTS),
                    load(&COUNTERS.max_tick_cycles),
                    off,
                    load(&COUNTERS.last_window_cycles)
                );
            }
        }
    }
}

/// Thread mode: command bytes from the DMA ring into the command decoder (gma-control's: COBS
/// framing, CRC, version, payload); each frame it completes is executed on the controller inside
/// a critical section, and the reply queued for the UART writer. Corrupt frames are counted by
/// the decoder and logged.
#[embassy_executor::task]
async fn command_rx(mut rx: RingBufferedUartRx<'static>, replies: Producer<'static, Reply>) {
    let mut port = CommandPort::new(replies);
    let mut chunk = [0u8; 32];
    loop {
        CHECK_IN.check_in(COMMAND_TASK);
        // Bounded, so that a silent line still checks in (CHECK_IN_WINDOW_TICKS).
        let read = with_timeout(Duration::from_millis(COMMAND_IDLE_CHECKIN_MS), rx.read(&mut chunk)).await;
        let n = match read {
            Err(_) => continue,
            Ok(Ok(n)) => n,
            Ok(Err(e)) => {
                // Overrun or framing error: the frame being assembled fails its CRC and is
                // counted as corrupt; the decoder resynchronises at the next delimiter.
                warn!("gma-drive: command UART {}", e);
                continue;
            }
        };
        let corrupt = port.decoder.corrupt;
        on_command_bytes(&mut port, &chunk[..n]);
        REPLIES_DROPPED.store(port.replies_dropped, core::sync::atomic::Ordering::Relaxed);
        if port.decoder.corrupt != corrupt {
            warn!("gma-drive: corrupt command frames {}", port.decoder.corrupt);
        }
    }
}

/// Received command bytes: every complete frame goes through the decoder to the controller,
/// inside a critical section as the interrupt shares it. A parameter load's model is built
/// before, outside the critical section (`CommandPort::on_bytes` stages it, with the interrupt
/// running); inside, only the move of the compensator into the controller runs.
fn on_command_bytes(port: &mut CommandPort, bytes: &[u8]) {
    port.on_bytes(bytes, |received, staged| {
        critical_section::with(|cs| {
            DRIVE.borrow_ref_mut(cs).as_mut().map(|drive| execute(drive, received, staged))
        })
    });
}

/// The 10 kHz end-of-conversion interrupt: the whole tick is `firmware::drive`'s.
#[interrupt]
fn ADC1_2() {
    critical_section::with(|cs| {
        if let Some(drive) = DRIVE.borrow_ref_mut(cs).as_mut() {
            drive.on_conversion();
        }
    });
}
