//! One line for an error and its causes.

/// An error and its causes as one line, each cause once (an OS error is often both in its
/// wrapper's message and its source).
pub fn chain_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for c in e.chain() {
        let s = c.to_string();
        if text.contains(&s) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&s);
    }
    text
}
