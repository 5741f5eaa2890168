//! Instruction-count benches of model-core on the Cortex-M4F (QEMU netduinoplus2): one case per
//! run, chosen by `-append "qemu-bench CASE"`. Each measured step sits between calls to the
//! marker functions `bench_start` and `bench_end`, which `scripts/fw bench` hands to the
//! in-tree QEMU instruction-count plugin (`firmware/qemu-insncount`); the `empty` case measures
//! the markers alone so that the script can subtract them. Instructions, not cycles.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use firmware::semihosting::{cmdline, exit};
use model_core::arx::{Arx, ArxParams, ArxState};
use model_core::magnetization::{JaParams, JaState, JilesAtherton, Preisach};
use model_core::mechanics::{ChainParams, ChainState, ChainZoh, MassSpringDamper, MechState, SecondOrderZoh};
use model_core::{Actuator, ActuatorParams, Compensator, ModelSpec};

/// The telemetry queue of the drive-loop cases (one case per run: written once).
static QUEUE: firmware::drive::Slot<firmware::drive::TelemetryQueue> = firmware::drive::Slot::new();

/// Measured steps per case.
const STEPS: usize = 500;

/// Ticks between keep-alive commands in the armed benches (well inside the 200 ms timeout).
const KEEP_ALIVE_TICKS: usize = 100;

/// Start marker: one `nop` (a body different from `bench_end`'s, so the two are not merged).
#[allow(unsafe_code)] // `no_mangle` only fixes the symbol name the script looks up.
#[no_mangle]
#[inline(never)]
pub extern "C" fn bench_start() {
    cortex_m::asm::nop();
}

/// End marker: two `nop`s.
#[allow(unsafe_code)]
#[no_mangle]
#[inline(never)]
pub extern "C" fn bench_end() {
    cortex_m::asm::nop();
    cortex_m::asm::nop();
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("qemu-bench: PANIC {}", info);
    exit(101)
}

/// Called by `firmware::fault`'s HardFault entry with the stack pointer reset.
#[allow(unsafe_code)] // no_mangle: the symbol the HardFault entry branches to.
#[no_mangle]
extern "C" fn gma_hard_fault() -> ! {
    let status = firmware::fault::FaultStatus::read();
    hprintln!("qemu-bench: HardFault (CFSR {:#010x}, HFSR {:#010x})", status.cfsr, status.hfsr);
    exit(102)
}

/// One period of a 400 Hz sine sampled at 10 kHz (25 samples), unit amplitude.
fn unit_sine() -> [f32; 25] {
    core::array::from_fn(|k| model_core::math::sin_cos(2.0 * core::f32::consts::PI * k as f32 / 25.0).0)
}

/// Runs `step(n)` STEPS times, each between the markers.
fn measure(mut step: impl FnMut(usize) -> f32) -> f32 {
    let mut acc = 0.0;
    for n in 0..STEPS {
        bench_start();
        let y = step(black_box(n));
        bench_end();
        acc += black_box(y);
    }
    acc
}

fn run(case: &str) -> Result<f32, &'static str> {
    let w = unit_sine();
    let p = ActuatorParams::TERFENOL_DEMO;
    let err = |_| "model parameters rejected";
    Ok(match case {
        "empty" => measure(|n| n as f32),
        "ja-substep" => {
            let ja = JilesAtherton::new(JaParams::TSMA_ROD1_002).map_err(err)?;
            let mut s = ja.state(2e4, 2e5, 1.9e5);
            measure(|n| {
                ja.substep(black_box(&mut s), if n % 50 < 25 { 200.0 } else { -200.0 });
                s.m_a_per_m
            })
        }
        "ja-sample-400hz" => {
            // Full scale: ±60 kA/m at 400 Hz, so each sample takes several sub-steps.
            let ja = JilesAtherton::new(JaParams::TSMA_ROD1_002).map_err(err)?;
            let mut s = JaState::default();
            measure(|n| ja.step(black_box(&mut s), 6e4 * w[n % 25]))
        }
        "zoh" => {
            let msd = MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 };
            let zoh = SecondOrderZoh::new(msd, 1e-4).map_err(err)?;
            let mut s = MechState::default();
            measure(|n| zoh.step(black_box(&mut s), 100.0 * w[n % 25]))
        }
        // amp + eddy + J–A + magnetostriction + mechanics, 1 V: at 100 Hz the field moves less
        // than one J–A sub-step per sample; at 400 Hz it takes several.
        "chain" | "chain-400hz" => {
            let spec = ModelSpec::parse("amp+eddy+ja+mech").map_err(|_| "bad spec")?;
            let model = Actuator::new(spec, &p).map_err(err)?;
            let mut s = model.rest_state();
            let stride = if case == "chain" { 1 } else { 4 };
            measure(|n| {
                model.step(black_box(&mut s), w[n * stride / 4 % 25]).map_or(f32::NAN, |o| o.displacement_m)
            })
        }
        // Inverse of amp + eddy + J–A + magnetostriction, 10 ± 10 µm at 100 Hz / 400 Hz.
        "inverse" | "inverse-400hz" => {
            let spec = ModelSpec::parse("amp+eddy+ja").map_err(|_| "bad spec")?;
            let model = Actuator::new(spec, &p).map_err(err)?;
            let y0 = model.rest_state().mech.displacement_m;
            let comp = Compensator::new(model);
            let mut s = comp.rest_state();
            let stride = if case == "inverse" { 1 } else { 4 };
            measure(|n| comp.step(black_box(&mut s), y0 + 10e-6 * (1.0 + w[n * stride / 4 % 25])))
        }
        // The same inverse with the Preisach law: what a `load` of a Preisach set costs per tick.
        "inverse-preisach" => {
            let spec = ModelSpec::parse("amp+eddy+preisach").map_err(|_| "bad spec")?;
            let model = Actuator::new(spec, &p).map_err(err)?;
            let y0 = model.rest_state().mech.displacement_m;
            let comp = Compensator::new(model);
            let mut s = comp.rest_state();
            measure(|n| comp.step(black_box(&mut s), y0 + 10e-6 * (1.0 + w[n / 4 % 25])))
        }
        "preisach" => {
            let pr = Preisach::new(p.preisach).map_err(err)?;
            let mut s = pr.demagnetized();
            measure(|n| pr.step(black_box(&mut s), 2e4 + 3e4 * w[n % 25]))
        }
        "ndof" => {
            let chain = ChainZoh::new(ChainParams::TSMA_002, 1e-4).map_err(err)?;
            let mut s = ChainState::default();
            measure(|n| {
                let f = 100.0 * w[n % 25];
                chain.step(black_box(&mut s), &ChainParams::tsma_forces([f, f, f]))
            })
        }
        "control-tick" => {
            // The whole board tick (gma-control), armed: faults, reference, compensator
            // (ja+eddy), PID, harmonic rejection, current loop, telemetry frame. Booted through
            // the offset calibration and armed by command first; the simulated rig and the
            // keep-alive run outside the markers.
            use gma_control::command::Command;
            use gma_control::sim::{CoilActuator, Rig};
            use gma_control::{Controller, ResetCause};
            let spec = ModelSpec::parse("ja+eddy+mech").map_err(|_| "bad spec")?;
            let mut rig = Rig::new(CoilActuator::new(spec, &p, 1e-4).map_err(err)?, 1);
            let cfg = firmware::drive::control_config();
            let mut ctl = Controller::new(cfg, spec, &p, ResetCause::PowerOn);
            for _ in 0..cfg.offset_calibration_ticks {
                let out = ctl.tick(&rig.sample());
                rig.apply(&out).map_err(|_| "rig input out of range")?;
            }
            ctl.command(1, &Command::Arm).outcome.map_err(|r| r.name())?;
            let mut acc = 0.0;
            for n in 0..STEPS {
                if n % KEEP_ALIVE_TICKS == 0 {
                    ctl.command(2, &Command::Ping);
                }
                let raw = rig.sample();
                bench_start();
                let out = ctl.tick(black_box(&raw));
                bench_end();
                if !out.bridge_enabled {
                    return Err("the controller disarmed during the bench");
                }
                acc += black_box(out.duty);
                rig.apply(&out).map_err(|_| "rig input out of range")?;
            }
            acc
        }
        // The whole 10 kHz interrupt as the board runs it (firmware::drive), armed: conversions,
        // control tick, bridge compare values and enable, watchdog, deadline check and the
        // telemetry record into the queue. Booted through the offset calibration and armed by an
        // encoded command frame through the command port; the rig, the keep-alive and the
        // thread-mode encoder run outside the markers.
        "isr" | "isr-square" | "isr-preisach" | "isr-preisach-square" | "telemetry-encode" => {
            use firmware::drive::{
                bus_code, control_config, encode_queued, execute, quiet_window_max_duty, BridgeTiming,
                CommandPort, DriveCounters, DriveLoop, MemoryStage, ReplyQueue, Slot, TelemetryQueue,
            };
            use gma_control::command::{self, Command};
            use gma_control::sim::{CoilActuator, Rig};
            use gma_control::telemetry::MAX_ENCODED;
            use gma_control::{Controller, ResetCause};
            static REPLIES: Slot<ReplyQueue> = Slot::new();
            static COUNTERS: DriveCounters = DriveCounters::new();
            let model = if case.starts_with("isr-preisach") { "preisach+eddy+mech" } else { "ja+eddy+mech" };
            let spec = ModelSpec::parse(model).map_err(|_| "bad spec")?;
            let mut rig = Rig::new(CoilActuator::new(spec, &p, 1e-4).map_err(err)?, 1);
            // SAFETY: the only write to QUEUE.
            #[allow(unsafe_code)]
            let (producer, mut consumer) = unsafe { QUEUE.write(TelemetryQueue::new()) }.split();
            let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
            // SAFETY: the only write to REPLIES.
            #[allow(unsafe_code)]
            let (reply_producer, mut replies) = unsafe { REPLIES.write(ReplyQueue::new()) }.split();
            let mut port = CommandPort::new(reply_producer);
            let ctl = Controller::new(control_config(), spec, &p, ResetCause::PowerOn);
            let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS);
            let mut bytes = [0u8; MAX_ENCODED];
            let mut send = |drive: &mut DriveLoop<MemoryStage>, cmd: &Command| -> Result<(), &'static str> {
                let mut frame = [0u8; command::MAX_ENCODED];
                let n = cmd.encode(1, &mut frame).map_err(|r| r.name())?;
                port.on_bytes(&frame[..n], |r, staged| Some(execute(drive, r, staged)));
                match replies.dequeue() {
                    Some(reply) => reply.outcome.map_err(|r| r.name()),
                    None => Err("no reply to a command"),
                }
            };
            let sample = |drive: &mut DriveLoop<MemoryStage>, rig: &mut Rig<CoilActuator>| {
                let raw = rig.sample();
                let stage = drive.stage();
                stage.conversions = [raw.current.0, raw.displacement.0, bus_code(raw.bus)];
                // One tick period per trigger on the stand-in cycle counter (the period check).
                stage.cycles = stage.cycles.wrapping_add(firmware::drive::TICK_CYCLES);
            };
            for _ in 0..control_config().offset_calibration_ticks {
                sample(&mut drive, &mut rig);
                let out = drive.on_conversion();
                rig.apply(&out).map_err(|_| "rig input out of range")?;
            }
            while consumer.dequeue().is_some() {}
            send(&mut drive, &Command::Arm)?;
            let in_isr = case != "telemetry-encode";
            if case.ends_with("-square") {
                // 25 µm steps every 5 ms: the compensator's worst ticks (many J–A sub-steps).
                let square = command::ReferenceCommand {
                    shape: command::Shape::Square,
                    amplitude_um: 12.5,
                    bias_um: 15.0,
                    freq_hz: 100.0,
                };
                send(&mut drive, &Command::SetReference(square))?;
            }
            let mut acc = 0.0;
            for n in 0..STEPS {
                if n % KEEP_ALIVE_TICKS == 0 {
                    send(&mut drive, &Command::Ping)?;
                }
                sample(&mut drive, &mut rig);
                if in_isr {
                    bench_start();
                }
                let out = drive.on_conversion();
                if in_isr {
                    bench_end();
                } else {
                    bench_start();
                }
                let n = encode_queued(black_box(&mut consumer), &mut bytes);
                if !in_isr {
                    bench_end();
                }
                if !out.bridge_enabled {
                    return Err("the drive disarmed during the bench");
                }
                acc += black_box(out.duty) + n as f32;
                rig.apply(&out).map_err(|_| "rig input out of range")?;
            }
            acc
        }
        // A Preisach parameter load as the board runs it: `load-build` the model build in thread
        // mode (`firmware::drive::stage`, interrupt running), `load-swap` what then runs inside
        // the critical section (`execute`: the checks and the move into the controller); four
        // loads each.
        "load-build" | "load-swap" => {
            use firmware::drive::{
                control_config, execute, quiet_window_max_duty, stage, BridgeTiming, DriveCounters, DriveLoop,
                MemoryStage, TelemetryQueue,
            };
            use gma_control::command::{Command, Received};
            use gma_control::{Controller, ResetCause, StagedParameters};
            static COUNTERS: DriveCounters = DriveCounters::new();
            let spec = ModelSpec::parse("ja+eddy+mech").map_err(|_| "bad spec")?;
            let preisach = ModelSpec::parse("preisach+eddy+mech").map_err(|_| "bad spec")?;
            let ctl = Controller::new(control_config(), spec, &p, ResetCause::PowerOn);
            // SAFETY: the only write to QUEUE.
            #[allow(unsafe_code)]
            let (producer, _consumer) = unsafe { QUEUE.write(TelemetryQueue::new()) }.split();
            let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
            let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS);
            let received = Received::Command(1, Command::LoadParameters { spec: preisach, params: p });
            let build = case == "load-build";
            let mut acc = 0.0;
            for _ in 0..4 {
                let mut staged = StagedParameters::empty();
                if build {
                    bench_start();
                }
                stage(black_box(&received), &mut staged);
                if build {
                    bench_end();
                } else {
                    bench_start();
                }
                let reply = execute(&mut drive, black_box(&received), &mut staged);
                if !build {
                    bench_end();
                }
                reply.outcome.map_err(|r| r.name())?;
                acc += 1.0;
            }
            acc
        }
        // The other commands' work inside the critical section (`execute`), each once after
        // boot: ping, clear, arm, set reference, disarm.
        "command-lock" => {
            use firmware::drive::{
                control_config, execute, quiet_window_max_duty, BridgeTiming, DriveCounters, DriveLoop,
                MemoryStage, TelemetryQueue,
            };
            use gma_control::command::{Command, Received, ReferenceCommand, Shape};
            use gma_control::sim::{CoilActuator, Rig};
            use gma_control::{Controller, ResetCause, StagedParameters};
            static COUNTERS: DriveCounters = DriveCounters::new();
            let spec = ModelSpec::parse("ja+eddy+mech").map_err(|_| "bad spec")?;
            let mut rig = Rig::new(CoilActuator::new(spec, &p, 1e-4).map_err(err)?, 1);
            let ctl = Controller::new(control_config(), spec, &p, ResetCause::PowerOn);
            // SAFETY: the only write to QUEUE.
            #[allow(unsafe_code)]
            let (producer, mut consumer) = unsafe { QUEUE.write(TelemetryQueue::new()) }.split();
            let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
            let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS);
            for _ in 0..control_config().offset_calibration_ticks {
                let raw = rig.sample();
                let stage = drive.stage();
                stage.conversions = [raw.current.0, raw.displacement.0, firmware::drive::bus_code(raw.bus)];
                stage.cycles = stage.cycles.wrapping_add(firmware::drive::TICK_CYCLES);
                let out = drive.on_conversion();
                rig.apply(&out).map_err(|_| "rig input out of range")?;
                while consumer.dequeue().is_some() {}
            }
            let square =
                ReferenceCommand { shape: Shape::Square, amplitude_um: 12.5, bias_um: 15.0, freq_hz: 100.0 };
            let mut acc = 0.0;
            for cmd in [Command::Ping, Command::ClearFaults, Command::Arm, Command::SetReference(square), Command::Disarm] {
                let received = Received::Command(1, cmd);
                let mut staged = StagedParameters::empty();
                bench_start();
                let reply = execute(&mut drive, black_box(&received), &mut staged);
                bench_end();
                reply.outcome.map_err(|r| r.name())?;
                acc += 1.0;
            }
            acc
        }
        "arx" => {
            let arx = Arx::new(ArxParams::DAVINO_003).map_err(err)?;
            let mut s: ArxState<2, 2> = arx.steady_state(0.0).map_err(err)?;
            measure(|n| arx.step(black_box(&mut s), 13.0 + 13.0 * w[n % 25]))
        }
        _ => {
            return Err(
                "unknown case (empty, ja-substep, ja-sample-400hz, zoh, chain, chain-400hz, inverse, \
                 inverse-400hz, preisach, ndof, arx, control-tick, isr, isr-square, telemetry-encode, load-build, \
                 load-swap)",
            )
        }
    })
}

#[entry]
fn main() -> ! {
    let mut buf = [0u8; 128];
    let line = cmdline(&mut buf);
    // QEMU passes "<kernel path> <-append text>": the case is the word after `qemu-bench`.
    let case = line.split_whitespace().skip_while(|w| *w != "qemu-bench").nth(1).unwrap_or("");
    match run(case) {
        Ok(acc) if acc.is_finite() => {
            hprintln!("qemu-bench: {} done ({} steps)", case, STEPS);
            exit(0)
        }
        Ok(_) => {
            hprintln!("qemu-bench: {} produced a non-finite output", case);
            exit(1)
        }
        Err(e) => {
            hprintln!("qemu-bench: `{}`: {}", case, e);
            exit(2)
        }
    }
}
