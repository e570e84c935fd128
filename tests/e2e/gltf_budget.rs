//! glTF inside the memory budget and without amplification (docs/RELIABILITY.md "glTF inside
//! the budget"): a buffer, a GLB's binary chunk or a JSON document that the budget cannot hold
//! is refused before it is read, naming its size and the budget; a scene whose primitives
//! would be read billions of times over is refused before the build, naming the estimate.

use std::path::Path;
use std::time::{Duration, Instant};

use super::{ok, text, voxlod};

/// A one-triangle glTF whose buffer is `bin` (`byte_length` bytes declared), with `extra`
/// JSON members at the top.
fn triangle_gltf(path: &Path, bin: &str, byte_length: u64, extra: &str) {
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},{extra}"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "buffers":[{{"uri":"{bin}","byteLength":{byte_length}}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    );
    std::fs::write(path, json).unwrap();
}

/// Three vertices of a triangle in the plane z = 0.
fn triangle_bytes() -> Vec<u8> {
    [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect()
}

/// Runs `build` of `input` with `extra` flags in `d`; the run must end within `secs`.
fn build(d: &Path, input: &str, extra: &[&str], secs: u64) -> std::process::Output {
    let mut args = vec!["build", input, "-o", "o.voxlod", "-r", "256"];
    args.extend_from_slice(extra);
    let t = Instant::now();
    let o = voxlod(&args, d);
    assert!(
        t.elapsed() < Duration::from_secs(secs),
        "{input} took {:?}: {}",
        t.elapsed(),
        text(&o)
    );
    o
}

fn refused(o: &std::process::Output, want: &[&str]) {
    let t = text(o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    for w in want {
        assert!(t.contains(w), "the message lacks {w:?}: {t}");
    }
}

#[test]
fn buffers_past_the_budget_are_refused_unread() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // within the budget: built (the control)
    std::fs::write(d.join("small.bin"), triangle_bytes()).unwrap();
    triangle_gltf(&d.join("small.gltf"), "small.bin", 36, "");
    ok(&build(d, "small.gltf", &["--memory", "336MiB"], 60));
    // a 4 GiB buffer (a sparse file) under a 512 MiB budget: refused before a byte of it is
    // read, naming its size and the budget
    let big = std::fs::File::create(d.join("big.bin")).unwrap();
    big.set_len(4 << 30).unwrap();
    triangle_gltf(&d.join("big.gltf"), "big.bin", 4 << 30, "");
    let o = build(d, "big.gltf", &["--memory", "512MiB"], 20);
    refused(
        &o,
        &[
            "big.gltf",
            "the buffers and images it names 4096.0 MiB",
            "more than the 184.0 MiB the memory budget leaves for reading the input",
            "raise --memory",
        ],
    );
    // a GLB of a 1 GiB binary chunk: the file itself is past the budget
    let json = br#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":1073741824}]}"#;
    let mut glb = Vec::new();
    let total = 12 + 8 + json.len() as u64 + 8 + (1 << 30);
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(json);
    glb.extend_from_slice(&(1u32 << 30).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    std::fs::write(d.join("big.glb"), &glb).unwrap();
    std::fs::OpenOptions::new()
        .write(true)
        .open(d.join("big.glb"))
        .unwrap()
        .set_len(total)
        .unwrap();
    let o = build(d, "big.glb", &["--memory", "512MiB"], 20);
    refused(&o, &["big.glb", "the file 1024.0 MiB", "raise --memory"]);
}

#[test]
fn documents_past_the_budget_are_refused_unparsed() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    std::fs::write(d.join("t.bin"), triangle_bytes()).unwrap();
    // a chain of 200,000 nodes (a 3 MB document): its parse alone is past what 336 MiB leave
    let mut nodes = String::from(r#"{"mesh":0}"#);
    for i in 1..200_000 {
        nodes += &format!(r#",{{"children":[{}]}}"#, i - 1);
    }
    let chain = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[199999]}}],"nodes":[{nodes}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "buffers":[{{"uri":"t.bin","byteLength":36}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    );
    std::fs::write(d.join("chain.gltf"), chain).unwrap();
    let o = build(d, "chain.gltf", &["--memory", "336MiB"], 20);
    refused(
        &o,
        &[
            "chain.gltf",
            "parsing its JSON document",
            "more than the 8.0 MiB the memory budget leaves for reading the input",
        ],
    );
    // the same chain with the budget to hold it: built, the whole chain read
    let o = build(d, "chain.gltf", &["--memory", "2GiB"], 120);
    ok(&o);
    // an `extras` array of a million numbers (2 MB of text)
    let extras = format!(r#""extras":[{}],"#, vec!["0"; 1_000_000].join(","));
    triangle_gltf(&d.join("extras.gltf"), "t.bin", 36, &extras);
    let o = build(d, "extras.gltf", &["--memory", "336MiB"], 20);
    refused(&o, &["extras.gltf", "parsing its JSON document"]);
}

#[test]
fn instancing_past_the_bound_is_refused_before_the_build() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // 5,000 primitives share one accessor of a million vertices for one triangle each: 12 MB
    // of file, five billion vertex records to read
    let n = 1_000_000u64;
    let f = std::fs::File::create(d.join("v.bin")).unwrap();
    f.set_len(n * 12 + 12).unwrap();
    let prims = vec![r#"{"attributes":{"POSITION":0},"indices":1}"#; 5000].join(",");
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{prims}]}}],
        "buffers":[{{"uri":"v.bin","byteLength":{}}}],
        "bufferViews":[{{"buffer":0,"byteLength":{}}},{{"buffer":0,"byteOffset":{},"byteLength":12}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":[0,0,0],"max":[0,0,0]}},
        {{"bufferView":1,"componentType":5125,"count":3,"type":"SCALAR"}}]}}"#,
        n * 12 + 12,
        n * 12,
        n * 12
    );
    std::fs::write(d.join("shared.gltf"), json).unwrap();
    let o = build(d, "shared.gltf", &[], 30);
    refused(
        &o,
        &[
            "shared.gltf",
            "the scene reads 5000015000 vertex and index records for 5000 triangles",
            "more than the 4294967296",
        ],
    );
}
