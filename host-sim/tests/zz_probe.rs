use host_sim::fit::{evaluate, fit, FitOptions};
use host_sim::recording::Recording;
use model_core::{ActuatorParams, ModelSpec};

#[test]
#[ignore]
fn probe() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/refrig-suite");
    let law = std::env::var("LAW").unwrap_or("ja-original".into());
    let spec = ModelSpec::parse(
        &std::env::var("SPEC").unwrap_or("ja+eddy+mech+amp+aftereffect+thermal+delay".into()),
    )
    .unwrap();
    let read = |l: &str| Recording::read(&dir.join(format!("{law}-full-s1-{l}.csv"))).unwrap();
    let fitl: Vec<String> =
        std::env::var("FIT").unwrap_or("sine20,multisine".into()).split(',').map(String::from).collect();
    let fits: Vec<Recording> = fitl.iter().map(|l| read(l)).collect();
    let vals: Vec<Recording> = ["sine70", "ramp12", "sine20", "multisine"].iter().map(|l| read(l)).collect();
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.coil.turns_per_m = 11_364.0;
    p.coil.bias_a_per_m = 20_000.0;
    let r = fit(spec, &p, &fits, FitOptions::default()).unwrap();
    let e = evaluate(spec, &r.params, &vals).unwrap();
    for (v, s) in vals.iter().zip(&e.files) {
        println!("{:20} {:.2} % cur {:?}", v.name, s.nrmse * 100.0, s.nrmse_current.map(|c| c * 100.0));
    }
    println!("evals {} fit {:.3} %", r.evaluations, r.fit.mean_nrmse() * 100.0);
}
