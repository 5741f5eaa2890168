//! Drive firmware for an STM32G474RE board (NUCLEO-G474RE class): clocks at 170 MHz, TIM1
//! center-aligned complementary PWM at 20 kHz (outputs off: the safe state) whose update event
//! triggers the ADC's injected conversions of coil current and displacement at 10 kHz.
#![no_std]
#![no_main]

use defmt::info;
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, SampleTime};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin, Mms2};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::Config;
use embassy_time::Timer;
use {defmt_rtt as _, panic_probe as _};

/// PWM carrier [Hz]: 20 kHz, above hearing; center-aligned, so the counter's update events come
/// at 40 kHz and a repetition count of 3 gives one ADC trigger per 4 half-periods = 10 kHz.
const PWM_HZ: u32 = 20_000;

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

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let p = embassy_stm32::init(clocks());
    info!("gma-drive: SYSCLK 170 MHz");

    // Full bridge: TIM1 CH1/CH1N (PA8/PA7) and CH2/CH2N (PA9/PB0).
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
    // Safe state until the control loop arms the bridge.
    pwm.set_master_output_enable(false);

    // ADC1: IN1 (PA0) coil current shunt amplifier, IN2 (PA1) displacement sensor.
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let mut injected = adc.setup_injected_conversions(
        [(p.PA0.degrade_adc(), SampleTime::CYCLES24_5), (p.PA1.degrade_adc(), SampleTime::CYCLES24_5)],
        embassy_stm32::triggers::TIM1_TRGO2,
        Exten::RISING_EDGE,
        false,
    );

    loop {
        let [current, displacement] = injected.read_injected_samples();
        info!("adc: current {} displacement {} (raw codes)", current, displacement);
        Timer::after_millis(500).await;
    }
}
