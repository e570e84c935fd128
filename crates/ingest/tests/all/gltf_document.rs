//! The glTF document's memory bound ([`voxlod_ingest::gltf_document_bound`]) against the memory
//! its parses really take: a counting allocator measures the peak of this thread's allocations
//! while the JSON is parsed as the reader parses it (a `serde_json` tree for the checks, then
//! the `gltf` crate's document), for documents whose cost per byte of text is high (a chain
//! of nodes, a long `extras` array, nested empty objects, many accessors and primitives).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting this thread's live bytes and their peak.
struct Counting;

thread_local! {
    static LIVE: Cell<i64> = const { Cell::new(0) };
    static PEAK: Cell<i64> = const { Cell::new(0) };
}

fn count(delta: i64) {
    let _ = LIVE.try_with(|l| {
        let now = l.get() + delta;
        l.set(now);
        let _ = PEAK.try_with(|p| p.set(p.get().max(now)));
    });
}

// SAFETY: every call is passed to the system allocator unchanged; only counts are added.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count(l.size() as i64);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        count(-(l.size() as i64));
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        count(l.size() as i64);
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        // old and new both live while the bytes move
        count(new as i64);
        let q = unsafe { System.realloc(p, l, new) };
        count(-(l.size() as i64));
        q
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// The peak of this thread's live bytes above where they were, while `f` runs.
fn peak_of(f: impl FnOnce()) -> u64 {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    f();
    (PEAK.with(Cell::get) - base) as u64
}

/// The parses of the reader, one after the other, each dropped before the next.
fn parse_as_the_reader(json: &str) {
    let tree: serde_json::Value = serde_json::from_str(json).unwrap();
    drop(tree);
    // the crate refuses some documents the checks pass (an `extras` that is not an object
    // where it reads none): the reader then stops, its peak so far measured all the same
    let Ok(root) = gltf::json::deserialize::from_str::<gltf::json::Root>(json) else {
        return;
    };
    let doc = gltf::Document::from_json_without_validation(root);
    // the reader's list of the scene's nodes with their transforms
    let nodes: Vec<_> = doc.nodes().map(|n| (n, [[0f64; 4]; 4])).collect();
    drop(nodes);
    drop(doc);
}

fn document(members: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":36}}],"bufferViews":[{{"buffer":0,"byteLength":36}}]{members}}}"#
    )
}

#[test]
fn the_document_bound_holds_for_costly_documents() {
    let chain: Vec<String> = (0..20_000)
        .map(|i| match i {
            0 => r#"{"mesh":0}"#.to_string(),
            i => format!(r#"{{"children":[{}]}}"#, i - 1),
        })
        .collect();
    let accessor = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}"#;
    let prim = r#"{"attributes":{"POSITION":0,"NORMAL":0,"TEXCOORD_0":0,"_X":0}}"#;
    let cases = [
        (
            "chain of 20,000 nodes",
            format!(r#","nodes":[{}]"#, chain.join(",")),
        ),
        (
            "extras of 200,000 numbers",
            format!(r#","extras":[{}]"#, vec!["0"; 200_000].join(",")),
        ),
        (
            "a node's extras of 200,000 numbers",
            format!(
                r#","nodes":[{{"extras":[{}]}}]"#,
                vec!["0"; 200_000].join(",")
            ),
        ),
        (
            "extras of 50,000 nested empty objects",
            format!(r#","extras":[{}]"#, vec![r#"{"a":{}}"#; 50_000].join(",")),
        ),
        (
            "20,000 empty nodes",
            format!(r#","nodes":[{}]"#, vec!["{}"; 20_000].join(",")),
        ),
        (
            "10,000 accessors, 5,000 primitives",
            format!(
                r#","accessors":[{}],"meshes":[{{"primitives":[{}]}}]"#,
                vec![accessor; 10_000].join(","),
                vec![prim; 5_000].join(",")
            ),
        ),
        (
            "named nodes",
            format!(
                r#","nodes":[{}]"#,
                vec![r#"{"name":"a name of some length, like an exporter writes"}"#; 10_000]
                    .join(",")
            ),
        ),
    ];
    for (what, members) in cases {
        let json = document(&members);
        let used = peak_of(|| parse_as_the_reader(&json));
        let bound = voxlod_ingest::gltf_document_bound(json.as_bytes());
        eprintln!(
            "{what}: {} bytes of text, parses peak at {used} bytes, bounded at {bound} ({:.1}×)",
            json.len(),
            bound as f64 / used as f64
        );
        assert!(used <= bound, "{what}: {used} bytes used, bound {bound}");
        // not so loose that a document the budget holds is refused: within 8× here
        assert!(
            bound <= 8 * used,
            "{what}: {used} bytes used, bound {bound}"
        );
    }
}
