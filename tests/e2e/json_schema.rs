//! The `--json` output of `build` (and `build --plan --shard`), `inspect`, `verify`, `diff`,
//! `plan` and `merge`, and the plan file, against the JSON Schemas in docs/schema/
//! (documented field by field in docs/JSON.md; the plan file in docs/FORMAT.md 15.1). The
//! validator below implements the subset of JSON Schema (2020-12) those files use: `type` (one or a list),
//! `properties`, `required`, `additionalProperties: false`, `items`, `enum`, `const`,
//! `minimum`, `minItems`, `maxItems`; any other keyword in a schema fails the test, so the
//! schemas cannot silently use something unchecked. The validator itself is tested on
//! documents that must fail.

use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

use super::{BIN, REPO};

const KNOWN: &[&str] = &[
    "$schema",
    "title",
    "description",
    "type",
    "properties",
    "required",
    "additionalProperties",
    "items",
    "enum",
    "const",
    "minimum",
    "minItems",
    "maxItems",
];

fn type_ok(t: &str, v: &Value) -> bool {
    match t {
        "object" => v.is_object(),
        "array" => v.is_array(),
        "string" => v.is_string(),
        "integer" => v.is_u64() || v.is_i64(),
        "number" => v.is_number(),
        "boolean" => v.is_boolean(),
        "null" => v.is_null(),
        _ => panic!("unknown type {t} in a schema"),
    }
}

/// Every violation of `schema` by `v`, each with its JSON path.
fn validate(schema: &Value, v: &Value, path: &str, errors: &mut Vec<String>) {
    let s = schema.as_object().expect("a schema is an object");
    for k in s.keys() {
        assert!(
            KNOWN.contains(&k.as_str()),
            "schema keyword {k} at {path} is not implemented"
        );
    }
    if let Some(t) = s.get("type") {
        let types: Vec<&str> = match t {
            Value::String(t) => vec![t.as_str()],
            Value::Array(ts) => ts.iter().map(|t| t.as_str().unwrap()).collect(),
            _ => panic!("bad type at {path}"),
        };
        if !types.iter().any(|t| type_ok(t, v)) {
            errors.push(format!("{path}: {v} is not of type {t}"));
            return;
        }
    }
    if let Some(c) = s.get("const") {
        if c != v {
            errors.push(format!("{path}: {v} is not {c}"));
        }
    }
    if let Some(e) = s.get("enum") {
        if !e.as_array().unwrap().contains(v) {
            errors.push(format!("{path}: {v} is not one of {e}"));
        }
    }
    if let (Some(m), Some(x)) = (s.get("minimum"), v.as_f64()) {
        if x < m.as_f64().unwrap() {
            errors.push(format!("{path}: {v} is below the minimum {m}"));
        }
    }
    if let Value::Array(items) = v {
        if let Some(n) = s.get("minItems") {
            if (items.len() as u64) < n.as_u64().unwrap() {
                errors.push(format!("{path}: fewer than {n} items"));
            }
        }
        if let Some(n) = s.get("maxItems") {
            if (items.len() as u64) > n.as_u64().unwrap() {
                errors.push(format!("{path}: more than {n} items"));
            }
        }
        if let Some(item) = s.get("items") {
            for (i, x) in items.iter().enumerate() {
                validate(item, x, &format!("{path}[{i}]"), errors);
            }
        }
    }
    if let Value::Object(o) = v {
        let props = s.get("properties").and_then(|p| p.as_object());
        if let Some(req) = s.get("required") {
            for r in req.as_array().unwrap() {
                if !o.contains_key(r.as_str().unwrap()) {
                    errors.push(format!("{path}: missing field {r}"));
                }
            }
        }
        for (k, x) in o {
            match props.and_then(|p| p.get(k)) {
                Some(sub) => validate(sub, x, &format!("{path}.{k}"), errors),
                None => {
                    if s.get("additionalProperties") == Some(&Value::Bool(false)) {
                        errors.push(format!("{path}: field {k} is not in the schema"));
                    }
                }
            }
        }
    }
}

fn schema(name: &str) -> Value {
    let p = Path::new(REPO).join(format!("docs/schema/{name}.json"));
    serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap()
}

fn check(name: &str, doc: &Value) {
    let mut errors = Vec::new();
    validate(&schema(name), doc, "$", &mut errors);
    assert!(
        errors.is_empty(),
        "{name} --json breaks docs/schema/{name}.json:\n{}\n{doc:#}",
        errors.join("\n")
    );
}

/// Every field the schema lists (recursively, where the document has one) has a description,
/// and `doc` (docs/JSON.md, or docs/FORMAT.md for the plan file) names it.
fn documented(name: &str, doc: &str) {
    let md = std::fs::read_to_string(Path::new(REPO).join(doc)).unwrap();
    fn walk(s: &Value, path: &str, md: &str, doc: &str) {
        if let Some(p) = s.get("properties").and_then(|p| p.as_object()) {
            for (k, sub) in p {
                assert!(
                    sub.get("description").is_some() || sub.get("properties").is_some(),
                    "{path}.{k} has no description"
                );
                assert!(
                    md.contains(&format!("`{k}`")),
                    "{doc} does not name `{k}` ({path})"
                );
                walk(sub, &format!("{path}.{k}"), md, doc);
            }
        }
        if let Some(i) = s.get("items") {
            walk(i, &format!("{path}[]"), md, doc);
        }
    }
    walk(&schema(name), name, &md, doc);
}

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        // says why: a spawn failure without the error printed no reason
        .unwrap_or_else(|e| panic!("cannot run {BIN} {args:?} in {}: {e}", cwd.display()))
}

fn json_of(o: &Output) -> Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {}\n{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

#[test]
fn the_validator_rejects_what_it_should() {
    let s = schema("verify");
    let good = serde_json::json!({"schema_version": 2, "opened": true, "nodes": 1,
        "nodes_decoded": 1, "voxels": 5, "parents_checked": 0, "leaf_voxels_checked": 5,
        "problems": [{"index": null, "level": null, "pos": null, "what": "x"}]});
    let mut e = Vec::new();
    validate(&s, &good, "$", &mut e);
    assert!(e.is_empty(), "{e:?}");
    let bad = |f: &dyn Fn(&mut Value), want: &str| {
        let mut d = good.clone();
        f(&mut d);
        let mut e = Vec::new();
        validate(&s, &d, "$", &mut e);
        assert!(e.iter().any(|m| m.contains(want)), "{want}: {e:?}");
    };
    bad(&|d| d["nodes"] = (-1).into(), "minimum");
    bad(&|d| d["nodes"] = 1.5.into(), "type");
    bad(&|d| d["schema_version"] = 1.into(), "is not 2");
    bad(&|d| d["extra"] = 1.into(), "not in the schema");
    bad(
        &|d| {
            d.as_object_mut().unwrap().remove("opened");
        },
        "missing field",
    );
    bad(
        &|d| d["problems"][0]["pos"] = serde_json::json!([1, 2]),
        "fewer than 3",
    );
    bad(
        &|d| d["problems"][0]["what"] = 3.into(),
        "$.problems[0].what",
    );
}

#[test]
fn json_output_of_each_command_matches_its_schema() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bunny = Path::new(REPO).join("data/bunny.ply");
    let bunny = bunny.to_str().unwrap();
    let mut builds = Vec::new();
    for (mode, out) in [("conservative", "c.voxlod"), ("thin", "t.voxlod")] {
        let o = run(
            &[
                "build",
                bunny,
                "-o",
                out,
                "-r",
                "256",
                "-m",
                mode,
                "--backend",
                "cpu",
                "-q",
                "--json",
            ],
            d,
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = json_of(&o);
        check("build", &v);
        assert_eq!(v["backend"]["kind"], "cpu");
        assert_eq!(v["mode"], mode);
        builds.push(v);
    }
    let v = json_of(&run(&["inspect", "c.voxlod", "--json"], d));
    check("inspect", &v);
    assert_eq!(v["voxels"], builds[0]["total_voxels"]);

    let v = json_of(&run(&["verify", "c.voxlod", "--json"], d));
    check("verify", &v);
    assert_eq!(v["problems"], serde_json::json!([]));
    // a damaged copy: problems listed, still the schema's shape
    let mut bytes = std::fs::read(d.join("c.voxlod")).unwrap();
    bytes[200] ^= 0x5a;
    std::fs::write(d.join("bad.voxlod"), bytes).unwrap();
    let o = run(&["verify", "bad.voxlod", "--json"], d);
    assert!(!o.status.success());
    let v = json_of(&o);
    check("verify", &v);
    assert!(!v["problems"].as_array().unwrap().is_empty());

    // a build with source geometry: its summary object, the channel in inspect, verify's count
    let o = run(
        &[
            "build",
            bunny,
            "-o",
            "s.voxlod",
            "-r",
            "256",
            "--backend",
            "cpu",
            "-q",
            "--json",
            "--source-geometry",
        ],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    check("build", &v);
    assert!(v["source_geometry"]["triangles_stored"].as_u64().unwrap() > 0);
    let v = json_of(&run(&["inspect", "s.voxlod", "--json"], d));
    check("inspect", &v);
    assert_eq!(v["channels"][0]["name"], "source triangles");
    let v = json_of(&run(&["verify", "s.voxlod", "--json"], d));
    check("verify", &v);
    assert!(v["source_triangles_checked"].as_u64().unwrap() > 0);

    // conservative against thin: changed nodes with all their fields
    let o = run(&["diff", "c.voxlod", "t.voxlod", "--json"], d);
    let v = json_of(&o);
    check("diff", &v);
    assert!(!v["changed"].as_array().unwrap().is_empty(), "{v:#}");
    check(
        "diff",
        &json_of(&run(&["diff", "c.voxlod", "c.voxlod", "--json"], d)),
    );
}

/// A sharded build of the bundled bunny: `plan --json`, the plan file, each `build --plan
/// --shard --json` (the build summary: docs/schema/build.json) and `merge --json` against their
/// schemas, and their figures against each other.
#[test]
fn sharded_build_json_and_the_plan_file_match_their_schemas() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bunny = Path::new(REPO).join("data/bunny.ply");
    let ok = |o: Output| {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        json_of(&o)
    };
    let set = ["-r", "512", "--backend", "cpu", "-q", "--json"];
    let mut args = vec!["plan", bunny.to_str().unwrap(), "-o", "plan.json"];
    args.extend(["--shards", "2"]);
    args.extend(set);
    let plan = ok(run(&args, d));
    check("plan", &plan);
    let file: Value = serde_json::from_slice(&std::fs::read(d.join("plan.json")).unwrap()).unwrap();
    check("plan-file", &file);
    assert_eq!(plan["triangles"], file["ingest"]["triangles"]);
    assert_eq!(plan["shards"], file["shards"]);
    assert_eq!(plan["chunks"], file["chunks"].as_array().unwrap().len());
    let mut binned = 0;
    for i in ["0", "1"] {
        let shard = ok(run(
            &["build", "--plan", "plan.json", "--shard", i, "-q", "--json"],
            d,
        ));
        check("build", &shard);
        binned += shard["binned_triangles"].as_u64().unwrap();
    }
    let total: u64 = file["chunks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c[1].as_u64().unwrap())
        .sum();
    assert_eq!(binned, total, "the shards binned what the plan counted");
    let merge = ok(run(
        &["merge", "plan.json", "-o", "m.voxlod", "-q", "--json"],
        d,
    ));
    check("merge", &merge);
    assert_eq!(merge["shards"], 2);
    let len = std::fs::metadata(d.join("m.voxlod")).unwrap().len();
    assert_eq!(merge["bytes"], len);

    // with parts: the plan, the plan file and each map task's summary
    std::fs::create_dir_all(d.join("pp")).unwrap();
    let mut args = vec!["plan", bunny.to_str().unwrap(), "-o", "pp/plan.json"];
    args.extend(["--shards", "2", "--parts", "3"]);
    args.extend(set);
    let plan = ok(run(&args, d));
    check("plan", &plan);
    assert_eq!(plan["parts"], 3);
    let file: Value =
        serde_json::from_slice(&std::fs::read(d.join("pp/plan.json")).unwrap()).unwrap();
    check("plan-file", &file);
    let mut mapped = 0;
    for i in ["0", "1", "2"] {
        let m = ok(run(
            &["map", "pp/plan.json", "--part", i, "-q", "--json"],
            d,
        ));
        check("map", &m);
        mapped += m["records"].as_u64().unwrap();
    }
    assert_eq!(mapped, file["parts"][2]["records"][1].as_u64().unwrap());
}

#[test]
fn every_schema_field_is_described_and_in_json_md() {
    for name in ["build", "inspect", "verify", "diff", "plan", "map", "merge"] {
        documented(name, "docs/JSON.md");
    }
    documented("plan-file", "docs/FORMAT.md");
}
