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
