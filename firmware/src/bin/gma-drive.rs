//! Drive firmware for an STM32G474RE board (NUCLEO-G474RE class), see firmware/README.md for
//! the pinout and scaling. The hardware glue only: TIM1 center-aligned complementary PWM at
//! 20 kHz drives the full bridge; its update event (every 4th half-period: 10 kHz) triggers the
//! ADC's injected conversion of coil current and displacement; the end-of-conversion interrupt
//! (highest priority) runs one `gma_control` tick — the same code the host and QEMU tests run —
//! sets the bridge duty, feeds the independent watchdog and queues the telemetry frame, which the
//! thread-mode loop streams over USART2 (the ST-LINK virtual COM port, 4 Mbaud, COBS frames).
#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m::peripheral::NVIC;
use critical_section::Mutex;
use defmt::{info, warn};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, InjectedAdc, SampleTime};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{ADC1, IWDG, TIM1};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin, Mms2};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::Channel;
use embassy_stm32::usart::{Config as UartConfig, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{interrupt, pac, Config};
use embassy_time::Timer;
use firmware::drive_params::{MODEL_SPEC, PARAMS_POSTCARD};
use gma_control::telemetry::MAX_ENCODED;
use gma_control::units::{AdcCode, Volts};
use gma_control::{ControlConfig, Controller, RawSample};
use heapless::Deque;
use {defmt_rtt as _, panic_probe as _};

/// PWM carrier [Hz]: 20 kHz, above hearing; center-aligned, so the counter's update events come
/// at 40 kHz and a repetition count of 3 gives one ADC trigger per 4 half-periods = 10 kHz.
const PWM_HZ: u32 = 20_000;
/// Bus voltage [V] (the reference board has no bus divider: nominal value).
const BUS_V: f32 = 24.0;
/// Encoded frames buffered between the interrupt and the UART (25 ms at 10 kHz).
const QUEUE: usize = 256;

/// Everything the 10 kHz interrupt owns.
struct Board {
    controller: Controller,
    adc: InjectedAdc<'static, ADC1, 2>,
    pwm: ComplementaryPwm<'static, TIM1>,
    watchdog: IndependentWatchdog<'static, IWDG>,
    frames: Deque<([u8; MAX_ENCODED], u8), QUEUE>,
    /// Frames the queue had no room for (the host also sees them as sequence gaps).
    overruns: u32,
}

static BOARD: Mutex<RefCell<Option<Board>>> = Mutex::new(RefCell::new(None));

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
    config
}

/// The controller for the compiled-in parameter set (`GMA_PARAMS`, `GMA_MODEL` at build time);
/// a set that does not decode or validate leaves the bridge off with PARAMETERS_INVALID.
fn controller() -> Controller {
    let spec = model_core::ModelSpec::parse(MODEL_SPEC);
    let params = postcard::from_bytes::<model_core::ActuatorParams>(PARAMS_POSTCARD);
    match (spec, params) {
        (Ok(spec), Ok(params)) => Controller::new(ControlConfig::REFERENCE, spec, &params),
        _ => Controller::refused(ControlConfig::REFERENCE),
    }
}

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let p = embassy_stm32::init(clocks());
    info!("gma-drive: SYSCLK 170 MHz, model `{}`", MODEL_SPEC);

    // Full bridge: TIM1 CH1/CH1N (PA8/PA7) one leg, CH2/CH2N (PA9/PB0) the other.
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
    pwm.set_repetition_counter(3);
    pwm.set_mms2(Mms2::UPDATE);
    pwm.set_dead_time(pwm.get_max_duty() as u16 / 100);
    let half = pwm.get_max_duty() / 2;
    pwm.set_duty(Channel::Ch1, half);
    pwm.set_duty(Channel::Ch2, half);
    pwm.enable(Channel::Ch1);
    pwm.enable(Channel::Ch2);
    // Safe state until a tick without faults arms the bridge.
    pwm.set_master_output_enable(false);

    // ADC1: IN1 (PA0) coil current shunt amplifier, IN2 (PA1) displacement probe; injected
    // conversions on TIM1 TRGO2, end-of-sequence interrupt on.
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let injected = adc.setup_injected_conversions(
        [(p.PA0.degrade_adc(), SampleTime::CYCLES24_5), (p.PA1.degrade_adc(), SampleTime::CYCLES24_5)],
        embassy_stm32::triggers::TIM1_TRGO2,
        Exten::RISING_EDGE,
        true,
    );

    // Watchdog: 2 ms, fed by every control tick — a stalled loop resets the board (PWM off).
    let mut watchdog = IndependentWatchdog::new(p.IWDG, 2_000);
    watchdog.unleash();

    let mut uart_config = UartConfig::default();
    uart_config.baudrate = 4_000_000;
    let mut uart = match UartTx::new_blocking(p.USART2, p.PA2, uart_config) {
        Ok(u) => u,
        Err(_) => defmt::panic!("USART2 configuration refused"),
    };

    let controller = controller();
    if !controller.faults().is_clear() {
        warn!("gma-drive: parameter set refused, bridge stays off (faults {:#x})", controller.faults().0);
    }
    critical_section::with(|cs| {
        BOARD.borrow(cs).replace(Some(Board {
            controller,
            adc: injected,
            pwm,
            watchdog,
            frames: Deque::new(),
            overruns: 0,
        }));
    });
    #[allow(unsafe_code)]
    // SAFETY: the handler only touches BOARD through the critical-section mutex, which is
    // initialised above; the ADC interrupt gets the highest priority (0).
    unsafe {
        let mut nvic = cortex_m::Peripherals::steal().NVIC;
        nvic.set_priority(pac::Interrupt::ADC1_2, 0);
        NVIC::unmask(pac::Interrupt::ADC1_2);
    }

    // Thread mode: stream the queued frames; report overruns once a second.
    let mut last_report = embassy_time::Instant::now();
    loop {
        let next =
            critical_section::with(|cs| BOARD.borrow_ref_mut(cs).as_mut().and_then(|b| b.frames.pop_front()));
        match next {
            Some((bytes, len)) => {
                let _ = uart.blocking_write(&bytes[..len as usize]);
            }
            None => Timer::after_micros(50).await,
        }
        if last_report.elapsed().as_secs() >= 1 {
            last_report = embassy_time::Instant::now();
            let (overruns, faults) = critical_section::with(|cs| {
                BOARD.borrow_ref(cs).as_ref().map(|b| (b.overruns, b.controller.faults().0)).unwrap_or((0, 0))
            });
            if overruns > 0 || faults != 0 {
                warn!("gma-drive: telemetry overruns {}, faults {:#x}", overruns, faults);
            }
        }
    }
}

#[interrupt]
fn ADC1_2() {
    critical_section::with(|cs| {
        let mut board = BOARD.borrow_ref_mut(cs);
        let Some(b) = board.as_mut() else { return };
        let [current, displacement] = b.adc.read_injected_samples();
        let raw =
            RawSample { current: AdcCode(current), displacement: AdcCode(displacement), bus: Volts(BUS_V) };
        let out = b.controller.tick(&raw);
        // Bipolar full bridge: leg A at (1 + d)/2, leg B at (1 − d)/2 of the period.
        let max = b.pwm.get_max_duty() as f32;
        let d = out.duty.clamp(-1.0, 1.0);
        b.pwm.set_duty(Channel::Ch1, (0.5 * (1.0 + d) * max) as u32);
        b.pwm.set_duty(Channel::Ch2, (0.5 * (1.0 - d) * max) as u32);
        b.pwm.set_master_output_enable(out.bridge_enabled);
        b.watchdog.pet();
        let mut buf = [0u8; MAX_ENCODED];
        let n = out.frame.encode(&mut buf);
        if b.frames.push_back((buf, n as u8)).is_err() {
            b.overruns = b.overruns.wrapping_add(1);
        }
    });
}
