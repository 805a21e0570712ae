//! Config parse errors in the user's terms: which section and line a TOML error is
//! in, an unknown key named with its section and a "did you mean" suggestion, a
//! missing key named with its section. The config's types reject unknown keys
//! (`deny_unknown_fields`); this module only rewrites the messages serde and the
//! `toml` crate give, it decides nothing about what a config may hold.

/// A table header line: its dotted name and whether it is an array of tables.
pub(crate) fn header(line: &str) -> Option<(String, bool)> {
    let t = line.trim();
    if let Some(rest) = t.strip_prefix("[[") {
        return Some((rest.split("]]").next()?.trim().to_string(), true));
    }
    let rest = t.strip_prefix('[')?;
    Some((rest.split(']').next()?.trim().to_string(), false))
}

/// The section a 1-based line belongs to: its header's name, its index among the
/// headers of that name (for `[[cameras]]`), and the header's line; `None` at the
/// top level. A line that is itself a header belongs to the top level (a section
/// name is a key of the top level).
fn section_of(text: &str, line: usize) -> Option<(String, usize, usize, bool)> {
    let mut current = None;
    let mut seen: std::collections::BTreeMap<String, usize> = Default::default();
    for (n, l) in text.lines().enumerate().take(line.saturating_sub(1)) {
        if let Some((name, array)) = header(l) {
            let count = seen.entry(name.clone()).or_insert(0);
            current = Some((name, *count, n + 1, array));
            *count += 1;
        }
    }
    current
}

/// How a section is named in a message: `[target]`, or `[[cameras]] #2 (line 9)`
/// (the header's line only when asked for).
fn section_name(section: &Option<(String, usize, usize, bool)>, with_line: bool) -> String {
    match section {
        None => "the top level".into(),
        Some((name, index, line, true)) if with_line => {
            format!("[[{name}]] #{} (line {line})", index + 1)
        }
        Some((name, index, _, true)) => format!("[[{name}]] #{}", index + 1),
        Some((name, _, _, false)) => format!("[{name}]"),
    }
}

/// The names between backquotes after `expected one of` / `expected` in a serde message.
fn expected_names(message: &str) -> Vec<String> {
    let Some((_, list)) = message.split_once("expected") else {
        return Vec::new();
    };
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The first name between backquotes in a serde message.
fn quoted(message: &str) -> Option<String> {
    Some(message.split('`').nth(1)?.to_string())
}

/// The known name closest to a misspelt one, when it is close enough to be a typo:
/// at most a third of its letters edited (transpositions count once).
pub fn did_you_mean<'a>(given: &str, known: &'a [String]) -> Option<&'a str> {
    let limit = (given.chars().count() / 3).max(1);
    known
        .iter()
        .map(|k| (strsim::damerau_levenshtein(given, k), k))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k.as_str())
}

/// The line of a byte offset, 1-based.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// A TOML or serde error as one message: `line N: ...`, naming the section, the
/// unknown key (with a suggestion) or the missing key.
pub fn explain(text: &str, message: &str, span: Option<std::ops::Range<usize>>) -> String {
    let message = message
        .trim()
        .lines()
        .map(str::trim)
        .collect::<Vec<_>>()
        .join("; ");
    let Some(span) = span else {
        return message;
    };
    let line = line_of(text, span.start);
    // A span on a header line is a section: an unknown one, or one lacking a key.
    let on_header = text.lines().nth(line - 1).and_then(header).is_some();
    let section = section_of(text, if on_header { line + 1 } else { line });
    if message.starts_with("unknown field") {
        let key = quoted(&message).unwrap_or_default();
        let known = expected_names(&message);
        let (what, brackets) = match &section {
            Some((name, ..)) if on_header => (format!("unknown section `[{name}]`"), true),
            None => (format!("unknown key `{key}` at the top level"), true),
            Some(_) => (
                format!("unknown key `{key}` in {}", section_name(&section, true)),
                false,
            ),
        };
        let suggestion = match did_you_mean(&key, &known) {
            Some(k) if brackets => format!("; did you mean `[{k}]`?"),
            Some(k) => format!("; did you mean `{k}`?"),
            None if known.is_empty() => String::new(),
            None => format!(" (known: {})", known.join(", ")),
        };
        return format!("line {line}: {what}{suggestion}");
    }
    if message.starts_with("missing field") {
        let key = quoted(&message).unwrap_or_default();
        return match &section {
            // An empty span is the whole document: a missing section.
            Some((_, _, header_line, _)) if on_header && !span.is_empty() => format!(
                "line {header_line}: {} lacks the required key `{key}`",
                section_name(&section, false)
            ),
            _ => format!("the config needs a `[{key}]` section"),
        };
    }
    // A misspelt value of a closed set (a method, a loss) gets a suggestion too.
    let suggestion = match quoted(&message) {
        Some(v) if message.starts_with("unknown variant") => {
            did_you_mean(&v, &expected_names(&message))
                .map(|k| format!("; did you mean `{k}`?"))
                .unwrap_or_default()
        }
        _ => String::new(),
    };
    match &section {
        Some(_) => format!(
            "line {line}: in {}: {message}{suggestion}",
            section_name(&section, false)
        ),
        None => format!("line {line}: {message}{suggestion}"),
    }
}

/// The line of `key` in table `table` (the `index`-th of an array of tables), or of
/// the table's header when `key` is empty.
pub(crate) fn key_line(text: &str, table: &str, index: usize, key: &str) -> Option<usize> {
    let mut current: Option<(String, usize)> = None;
    let mut seen: std::collections::BTreeMap<String, usize> = Default::default();
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some((h, _)) = header(t) {
            let count = seen.entry(h.clone()).or_insert(0);
            current = Some((h.clone(), *count));
            *count += 1;
            if key.is_empty() && h == table && current.as_ref().map(|c| c.1) == Some(index) {
                return Some(n + 1);
            }
            continue;
        }
        if let Some((h, i)) = &current {
            if h == table && *i == index && !key.is_empty() {
                if let Some(rest) = t.strip_prefix(key) {
                    if rest.trim_start().starts_with('=') {
                        return Some(n + 1);
                    }
                }
            }
        }
    }
    None
}

/// Splits a message that starts with `table.key`, `table[i].key` or `[table]`.
pub(crate) fn message_key(message: &str) -> Option<(String, usize, String)> {
    if let Some(rest) = message.strip_prefix('[') {
        let table = rest.split(']').next()?.trim_start_matches('[');
        return Some((table.to_string(), 0, String::new()));
    }
    let head: String = message
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '[' | ']'))
        .collect();
    let (table, key) = head.split_once('.')?;
    let key: String = key
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    let (table, index) = match table.split_once('[') {
        Some((t, i)) => (t, i.trim_end_matches(']').parse().ok()?),
        None => (table, 0),
    };
    Some((table.to_string(), index, key))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typos_get_the_closest_known_name() {
        let known: Vec<String> = ["rows", "cols", "spacing"].map(String::from).to_vec();
        assert_eq!(did_you_mean("spaceing", &known), Some("spacing"));
        assert_eq!(did_you_mean("spcaing", &known), Some("spacing"));
        assert_eq!(did_you_mean("colour", &known), None);
        assert_eq!(did_you_mean("row", &known), Some("rows"));
    }

    #[test]
    fn sections_are_found_from_the_headers() {
        let text = "[target]\nrows = 1\n[[cameras]]\nname = \"a\"\n[[cameras]]\nname = \"b\"\n";
        assert_eq!(section_of(text, 2).unwrap().0, "target");
        assert_eq!(section_of(text, 6).unwrap().1, 1);
        assert_eq!(section_of(text, 1), None);
        assert_eq!(
            section_name(&section_of(text, 6), true),
            "[[cameras]] #2 (line 5)"
        );
    }
}
