//! The validation rules for the two parts of a file that are not fixed-size binary: the JSON
//! manifest and each payload's zstd frame (docs/FORMAT.md 11.2, "One rule set"). The Rust
//! [`Reader`](crate::Reader), `voxlod verify` (through the reader) and the Python reader
//! (`scripts/voxlod_read.py`) apply exactly these rules, in this order, so that a file one of
//! them rejects, all reject. The frame rules follow RFC 8878 (Zstandard): section 3.1.1 (frame
//! header, content size) and 3.1.2 (skippable frames).

/// Deepest nesting of JSON arrays and objects a manifest may have (`{}` has depth 1). Checked
/// by a byte scan before parsing, so no parser recurses deeper (Python's `json` would raise
/// `RecursionError` near 1000, serde_json stops at 128).
pub const MAX_MANIFEST_DEPTH: usize = 64;

/// zstd frame magic number (RFC 8878 3.1.1), little-endian in the file.
const ZSTD_MAGIC: u32 = 0xFD2F_B528;
/// Skippable frames have magic `0x184D2A50..=0x184D2A5F` (RFC 8878 3.1.2).
const SKIPPABLE_MAGIC: u32 = 0x184D_2A50;

/// Manifest rules, in order: not empty; valid UTF-8; nesting depth at most
/// [`MAX_MANIFEST_DEPTH`]; one JSON value (RFC 8259) with nothing but whitespace after it; that
/// value an object. Returns the message for the first rule broken.
pub fn check_manifest(bytes: &[u8]) -> Result<serde_json::Value, String> {
    if bytes.is_empty() {
        return Err("it is empty (a manifest is a JSON object)".into());
    }
    if let Err(e) = std::str::from_utf8(bytes) {
        return Err(format!(
            "it is not valid UTF-8 (at byte {})",
            e.valid_up_to()
        ));
    }
    let depth = json_depth(bytes);
    if depth > MAX_MANIFEST_DEPTH {
        return Err(format!(
            "its JSON nests {depth} levels deep, more than the {MAX_MANIFEST_DEPTH} allowed"
        ));
    }
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| format!("it is not valid JSON: {e}"))?;
    if !value.is_object() {
        return Err("its JSON is not an object".into());
    }
    Ok(value)
}

/// The deepest nesting of `[` and `{` outside strings (the whole document is scanned, also
/// past the deepest point, so the answer is exact for any bytes; malformed JSON is rejected
/// by the parser afterwards).
pub fn json_depth(bytes: &[u8]) -> usize {
    let (mut depth, mut max) = (0usize, 0usize);
    let (mut in_string, mut escaped) = (false, false);
    for &b in bytes {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b'[' | b'{' => {
                depth += 1;
                max = max.max(depth);
            }
            b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    max
}

/// Payload rules, in order, for a node of `n` voxels: the payload starts with the zstd frame
/// magic (a skippable frame is named as such); the frame header declares a content size; that
/// size is exactly `12·n` (so no reader allocates more than the spec's bound); the frame is
/// the whole payload (no second frame, no trailing bytes). Decompression and the checksums
/// come after these.
pub fn check_frame(payload: &[u8], n: usize) -> Result<(), String> {
    check_frame_of(payload, 12 * n as u64, &format!("12·{n}"))
}

/// The payload rules of [`check_frame`] for a frame that must decompress to exactly `want`
/// bytes (`formula` names it in messages, e.g. `12·5`): also used for channel payloads
/// (docs/FORMAT.md 14.2).
pub fn check_frame_of(payload: &[u8], want: u64, formula: &str) -> Result<(), String> {
    let n = formula;
    let Some(magic) = payload.get(..4) else {
        return Err(format!(
            "the payload is {} bytes, too short for a zstd frame",
            payload.len()
        ));
    };
    let magic = u32::from_le_bytes(magic.try_into().expect("4 bytes"));
    if magic & 0xFFFF_FFF0 == SKIPPABLE_MAGIC {
        return Err(
            "the payload starts with a skippable zstd frame (it must be exactly one zstd frame)"
                .into(),
        );
    }
    if magic != ZSTD_MAGIC {
        return Err(format!(
            "the payload does not start with the zstd magic (28 b5 2f fd) but with {:02x} {:02x} {:02x} {:02x}",
            payload[0], payload[1], payload[2], payload[3]
        ));
    }
    match zstd::zstd_safe::get_frame_content_size(payload) {
        Err(_) => return Err("the zstd frame header is corrupt or cut short".into()),
        Ok(None) => {
            return Err(format!(
                "the zstd frame header has no content size (it must say {n} = {want})"
            ))
        }
        Ok(Some(size)) if size != want => {
            return Err(format!(
                "the zstd frame header's content size is {size} bytes, expected {n} = {want}"
            ))
        }
        Ok(Some(_)) => {}
    }
    match zstd::zstd_safe::find_frame_compressed_size(payload) {
        Err(code) => Err(format!(
            "the zstd frame is corrupt or cut short: {}",
            zstd::zstd_safe::get_error_name(code)
        )),
        Ok(size) if size != payload.len() => Err(format!(
            "the zstd frame ends at byte {size} of the {}-byte payload (a second frame or trailing bytes follow)",
            payload.len()
        )),
        Ok(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_counts_brackets_outside_strings() {
        assert_eq!(json_depth(b"1"), 0);
        assert_eq!(json_depth(b"{}"), 1);
        assert_eq!(json_depth(br#"{"a":[{"b":"[[[{"}]}"#), 3);
        assert_eq!(json_depth(br#"{"a\"[":[]}"#), 2);
        assert_eq!(json_depth(&[b'['; 100_000]), 100_000);
    }

    #[test]
    fn manifest_rules() {
        assert!(check_manifest(br#"{"tool":"voxlod"}"#).is_ok());
        for (bad, says) in [
            (&b""[..], "empty"),
            (b"{\"a\":\"\xff\"}", "UTF-8"),
            (b"{\"a\":1", "JSON"),
            (b"{} {}", "JSON"),
            (b"null", "not an object"),
        ] {
            let e = check_manifest(bad).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
        let deep = format!("{}{}", "[".repeat(65), "]".repeat(65));
        assert!(check_manifest(deep.as_bytes())
            .unwrap_err()
            .contains("65 levels"));
        let ok = format!("{{\"a\":{}{}}}", "[".repeat(63), "]".repeat(63));
        assert!(check_manifest(ok.as_bytes()).is_ok());
    }

    #[test]
    fn frame_rules() {
        let block = vec![7u8; 24];
        let frame = zstd::bulk::compress(&block, 3).unwrap();
        assert_eq!(check_frame(&frame, 2), Ok(()));
        assert!(check_frame(&frame, 3)
            .unwrap_err()
            .contains("content size is 24"));
        let two = [frame.clone(), frame.clone()].concat();
        assert!(check_frame(&two, 2).unwrap_err().contains("second frame"));
        let mut skip = vec![0x50, 0x2A, 0x4D, 0x18, 0, 0, 0, 0];
        skip.extend_from_slice(&frame);
        assert!(check_frame(&skip, 2).unwrap_err().contains("skippable"));
        let mut e = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
        e.include_contentsize(false).unwrap();
        std::io::Write::write_all(&mut e, &block).unwrap();
        let no_size = e.finish().unwrap();
        assert!(check_frame(&no_size, 2)
            .unwrap_err()
            .contains("no content size"));
        assert!(check_frame(&frame[..frame.len() - 1], 2).is_err());
        assert!(check_frame(b"abc", 2).is_err());
    }
}
