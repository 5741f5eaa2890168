//! The docs that are generated from the code stay generated: docs/cli.md's effect and parameter
//! tables are `gma effects --markdown`, byte for byte.

use std::process::Command;

#[test]
fn the_docs_effect_tables_are_the_registry() {
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).args(["effects", "--markdown"]).output().unwrap();
    assert!(o.status.success());
    let generated = String::from_utf8(o.stdout).unwrap();
    let docs = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cli.md")).unwrap();
    let begin = docs.find("<!-- effects:begin").expect("docs/cli.md: no effects:begin marker");
    let body = &docs[begin..];
    let body = &body
        [body.find('\n').unwrap() + 1..body.find("<!-- effects:end -->").expect("no effects:end marker")];
    assert_eq!(
        body.trim_end(),
        generated.trim_end(),
        "docs/cli.md's effect tables differ from the registry: paste `gma effects --markdown` between the markers"
    );
}

#[test]
fn effects_json_lists_every_effect_with_its_parameters() {
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).args(["effects", "--json"]).output().unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let names: Vec<&str> =
        j["effects"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    let all: Vec<&str> = model_core::Effect::ALL.iter().map(|e| e.name()).collect();
    assert_eq!(names, all);
    let mech = j["effects"].as_array().unwrap().iter().find(|e| e["alias"] == "mech").unwrap();
    assert_eq!(mech["params"][0]["unit"], "Hz");
}

/// The plain text lists what the Markdown and the JSON list: every parameter a fit identifies
/// (the laws', the strain scale and the amplifier gain included, not only the effects'), and the
/// rod's thermal lag with what its out-of-range default 0 means.
#[test]
fn effects_text_lists_every_identified_parameter() {
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).args(["effects", "--json"]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).arg("effects").output().unwrap();
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    let mut keys = 0;
    for row in j["identified"].as_array().unwrap() {
        assert!(text.contains(&format!("{}:", row["when"].as_str().unwrap())), "{}\n{text}", row["when"]);
        for p in row["params"].as_array().unwrap() {
            let key = p["key"].as_str().unwrap();
            assert!(text.lines().any(|l| l.trim_start().starts_with(&format!("{key} ["))), "{key}\n{text}");
            keys += 1;
        }
    }
    assert!(keys > 20, "{keys}");
    for key in
        ["ja.k_a_per_m", "preisach.coercive_a_per_m", "anhysteretic.a_a_per_m", "linear.susceptibility"]
    {
        assert!(text.contains(key), "{key}\n{text}");
    }
    let rod = text.lines().find(|l| l.contains("thermal.rod_tau_s")).unwrap();
    assert!(
        rod.contains("default 0 = no lag") && rod.contains("searched in [0.01, 3000] (log) when a file logs"),
        "{rod}"
    );
    let rod = j["identified"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r["params"].as_array().unwrap())
        .find(|p| p["key"] == "thermal.rod_tau_s")
        .unwrap();
    assert!(rod["note"].as_str().unwrap().contains("default 0 = no lag"), "{rod}");
    let lambda = &j["identified"][0]["params"][0];
    assert!(lambda["note"].is_null(), "{lambda}");
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).args(["effects", "--markdown"]).output().unwrap();
    let md = String::from_utf8(o.stdout).unwrap();
    let rod = md.lines().find(|l| l.contains("`thermal.rod_tau_s`")).unwrap();
    assert!(rod.contains("0 = no lag") && rod.contains("[0.01, 3000] when a file logs"), "{rod}");
}

/// The JSON's defaults are the numbers the tables print and a parameter file states (0.0002),
/// not the digits of their single-precision image (0.00019999999494757503).
#[test]
fn effects_json_gives_defaults_as_the_tables_state_them() {
    let o = Command::new(env!("CARGO_BIN_EXE_gma")).args(["effects", "--json"]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let params: Vec<&serde_json::Value> =
        j["identified"].as_array().unwrap().iter().flat_map(|r| r["params"].as_array().unwrap()).collect();
    let default = |key: &str| params.iter().find(|p| p["key"] == key).unwrap()["default"].as_f64().unwrap();
    assert_eq!(default("amp.tau_s"), 0.0002);
    assert_eq!(default("eddy_tau_s"), 0.00015);
    assert_eq!(default("ja.alpha"), -0.035);
    for p in params {
        let d = p["default"].as_f64().unwrap();
        assert_eq!(d, (d as f32).to_string().parse::<f64>().unwrap(), "{p}");
    }
}
