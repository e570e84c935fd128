//! The `--json` output of `build`, `inspect`, `verify` and `diff`: the report structs as JSON
//! objects (keys in alphabetical order) with a `schema_version`, and the build's voxelizer as a structured object instead of
//! a sentence. Every field is documented with its unit in docs/JSON.md and checked against
//! docs/schema/<command>.json by tests/e2e/json_schema.rs.

use anyhow::Result;
use serde::Serialize;
use serde_json::{json, Map, Value};
use voxlod_pipeline::BuildSummary;

/// Version of the JSON documents (1: before `schema_version` existed, `backend` a sentence).
pub const SCHEMA_VERSION: u32 = 2;

/// `value` as a JSON object with a `schema_version` field added.
pub fn versioned(value: &impl Serialize) -> Result<Value> {
    let mut out = Map::new();
    out.insert("schema_version".into(), SCHEMA_VERSION.into());
    match serde_json::to_value(value)? {
        Value::Object(m) => out.extend(m),
        other => anyhow::bail!("a JSON report must be an object, not {other}"),
    }
    Ok(Value::Object(out))
}

/// Prints `value` (pretty, with `schema_version`) on stdout.
pub fn print(value: &impl Serialize) -> Result<()> {
    println!("{}", serde_json::to_string_pretty(&versioned(value)?)?);
    Ok(())
}

/// The build summary as JSON: `backend` becomes [`backend_object`].
pub fn build(s: &BuildSummary) -> Result<Value> {
    let mut v = versioned(s)?;
    v["backend"] = backend_object(s);
    Ok(v)
}

/// The voxelizer that ran, from the summary's description (written by the pipeline's
/// backend module as `cpu (N chunk voxelizers on T threads, METHOD)[; NOTE]` or
/// `gpu ADAPTER (METHOD[, cutoff C voxels²[ found by search]], f64: …|f32: …)`):
/// `{kind, adapter, method, chunk_voxelizers, cutoff, cutoff_searched, precision, note,
/// description}`.
pub fn backend_object(s: &BuildSummary) -> Value {
    let d = s.backend.as_str();
    let (main, note) = match d.split_once("; ") {
        Some((m, n)) => (m, Some(n)),
        None => (d, None),
    };
    let mut o = json!({
        "kind": "cpu",
        "adapter": null,
        "method": s.voxelizer.to_string(),
        "chunk_voxelizers": null,
        "cutoff": null,
        "cutoff_searched": false,
        "precision": null,
        "note": note,
        "description": d,
    });
    if s.gpu_split.is_some() || main.starts_with("gpu ") {
        o["kind"] = "gpu".into();
        let body = main.strip_prefix("gpu ").unwrap_or(main);
        // the adapter name may hold parentheses itself ("llvmpipe (LLVM 19, 256 bits)"):
        // the method's parenthesis is the last one that starts with a method name
        let at = ["hybrid", "triangle", "fragment"]
            .iter()
            .filter_map(|m| body.rfind(&format!(" ({m}")).map(|i| (i, *m)))
            .max();
        if let Some((i, method)) = at {
            o["adapter"] = body[..i].into();
            o["method"] = method.into();
            let rest = &body[i..];
            for p in ["f64", "f32"] {
                if rest.contains(&format!(", {p}: ")) {
                    o["precision"] = p.into();
                }
            }
            if let Some(c) = rest.split(", cutoff ").nth(1) {
                let num = c.split(' ').next().unwrap_or("");
                if let Ok(c) = num.parse::<f64>() {
                    o["cutoff"] = c.into();
                }
                o["cutoff_searched"] = c.contains("found by search").into();
            }
        } else {
            o["adapter"] = body.into();
        }
    } else if let Some(n) = main
        .strip_prefix("cpu (")
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse::<u64>().ok())
    {
        o["chunk_voxelizers"] = n.into();
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(backend: &str, gpu: bool) -> BuildSummary {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("one.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
             end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        )
        .unwrap();
        let settings = voxlod_pipeline::BuildSettings {
            resolution: 256,
            backend: voxlod_pipeline::Backend::Cpu,
            ..Default::default()
        };
        let mut s = voxlod_pipeline::build(&p, &dir.path().join("one.voxlod"), &settings).unwrap();
        s.backend = backend.into();
        s.gpu_split = gpu.then_some([1, 2]);
        s
    }

    #[test]
    fn backend_descriptions_become_objects() {
        let s = summary(
            "cpu (2 chunk voxelizers on 2 threads, scanline); no GPU: no adapter",
            false,
        );
        let o = backend_object(&s);
        assert_eq!(o["kind"], "cpu");
        assert_eq!(o["chunk_voxelizers"], 2);
        assert_eq!(o["method"], "scanline");
        assert_eq!(o["note"], "no GPU: no adapter");
        assert_eq!(o["adapter"], Value::Null);

        let s = summary(
            "gpu llvmpipe (LLVM 19.1.1, 256 bits) (hybrid, cutoff 12.5 voxels² found by search, \
             f64: exact sets, uncertain triangles on the CPU)",
            true,
        );
        let o = backend_object(&s);
        assert_eq!(o["kind"], "gpu");
        assert_eq!(o["adapter"], "llvmpipe (LLVM 19.1.1, 256 bits)");
        assert_eq!(o["method"], "hybrid");
        assert_eq!(o["cutoff"], 12.5);
        assert_eq!(o["cutoff_searched"], true);
        assert_eq!(o["precision"], "f64");

        let o = backend_object(&summary("gpu NVIDIA RTX (fragment)", true));
        assert_eq!(o["adapter"], "NVIDIA RTX");
        assert_eq!(o["method"], "fragment");
        assert_eq!(o["cutoff"], Value::Null);
        assert_eq!(o["precision"], Value::Null);

        let v = build(&s).unwrap();
        assert_eq!(v["schema_version"], SCHEMA_VERSION);
        assert_eq!(v["backend"]["kind"], "gpu");
    }
}
