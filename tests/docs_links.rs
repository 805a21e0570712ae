//! The user documentation stays navigable: every relative link in README.md,
//! CHANGELOG.md and docs/*.md names a file that exists and, with a `#fragment`, a
//! heading of that file (GitHub's anchors); and no page points users at an issue
//! number they cannot follow. No network: external links are not checked.
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The pages checked: the README, the changelog and every Markdown file in docs/.
fn pages() -> Vec<PathBuf> {
    let root = root();
    let mut pages = vec![root.join("README.md"), root.join("CHANGELOG.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ exists")
        .map(|e| e.expect("readable docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    pages.extend(docs);
    pages
}

/// The lines outside fenced code blocks, with their 1-based numbers: links and
/// headings inside code are text, not Markdown.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut in_fence = false;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if !in_fence {
            out.push((n + 1, line));
        }
    }
    out
}

/// A line without its inline code spans, which may hold `](` as plain text.
fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    for (k, part) in line.split('`').enumerate() {
        if k % 2 == 0 {
            out.push_str(part);
        }
    }
    out
}

/// Link targets of a line: the `target` of every `[text](target)`.
fn link_targets(line: &str) -> Vec<String> {
    let line = without_code_spans(line);
    let mut targets = Vec::new();
    let mut rest = line.as_str();
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        match after.find(')') {
            Some(j) => {
                targets.push(after[..j].trim().to_string());
                rest = &after[j + 1..];
            }
            None => break,
        }
    }
    targets
}

/// `[text](url)` reduced to `text`, as GitHub renders a heading before its slug.
fn link_text_only(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("](") {
        let Some(j) = rest[i..].find(')') else { break };
        out.push_str(&rest[..i].replace('[', ""));
        rest = &rest[i + j + 1..];
    }
    out.push_str(&rest.replace('[', ""));
    out
}

/// GitHub's anchor of a heading: lower case, punctuation and symbols dropped,
/// spaces to hyphens.
fn slug(heading: &str) -> String {
    link_text_only(heading)
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_' || *c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every anchor a Markdown file offers, repeated headings numbered as GitHub does.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if hashes == 0 || hashes > 6 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = slug(line[hashes..].trim().trim_end_matches('#'));
        let mut anchor = base.clone();
        let mut k = 1;
        while seen.contains(&anchor) {
            anchor = format!("{base}-{k}");
            k += 1;
        }
        seen.insert(anchor);
    }
    seen
}

fn is_external(target: &str) -> bool {
    target.contains("://") || target.starts_with("mailto:")
}

/// Every broken relative link of one page, as `page:line: target (why)`.
fn broken_links(page: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(page).expect("readable page");
    let dir = page.parent().expect("page in a folder");
    let name = page
        .strip_prefix(root())
        .unwrap_or(page)
        .display()
        .to_string();
    let mut broken = Vec::new();
    for (n, line) in prose_lines(&text) {
        for target in link_targets(line) {
            if target.is_empty() || is_external(&target) {
                continue;
            }
            let (file, fragment) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let path = if file.is_empty() {
                page.to_path_buf()
            } else {
                dir.join(file)
            };
            if !path.exists() {
                broken.push(format!("{name}:{n}: {target} (no such file)"));
                continue;
            }
            let Some(fragment) = fragment else { continue };
            if path.extension().is_none_or(|e| e != "md") {
                broken.push(format!(
                    "{name}:{n}: {target} (an anchor in a non-Markdown file)"
                ));
                continue;
            }
            let target_text = std::fs::read_to_string(&path).expect("readable link target");
            if !anchors(&target_text).contains(fragment) {
                broken.push(format!("{name}:{n}: {target} (no such heading)"));
            }
        }
    }
    broken
}

#[test]
fn github_slugs_follow_its_rules() {
    assert_eq!(
        slug("## The target (board)".trim_start_matches("## ")),
        "the-target-board"
    );
    assert_eq!(
        slug("3a. Uncertainty and model selection"),
        "3a-uncertainty-and-model-selection"
    );
    assert_eq!(
        slug("The rational model's lens prior"),
        "the-rational-models-lens-prior"
    );
    assert_eq!(
        slug("`[data]`: where the observations come from"),
        "data-where-the-observations-come-from"
    );
    assert_eq!(slug("board.json"), "boardjson");
    let repeated = anchors("# A\n## Notes\n```\n## Not a heading\n```\n## Notes\n");
    let expected: BTreeSet<String> = ["a", "notes", "notes-1"].map(String::from).into();
    assert_eq!(repeated, expected);
}

#[test]
fn broken_links_are_found() {
    let dir = std::env::temp_dir().join(format!("docs_links_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("page.md");
    std::fs::write(
        &page,
        "# Page\n## Real heading\n[ok](#real-heading) [gone](missing.md) [bad](#nowhere)\n\
         `[code](missing.md)` [web](https://example.com/x)\n```\n[fenced](missing.md)\n```\n",
    )
    .unwrap();
    let broken = broken_links(&page);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(broken.len(), 2, "{broken:?}");
    assert!(
        broken[0].ends_with("missing.md (no such file)"),
        "{broken:?}"
    );
    assert!(
        broken[1].ends_with("#nowhere (no such heading)"),
        "{broken:?}"
    );
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let broken: Vec<String> = pages().iter().flat_map(|p| broken_links(p)).collect();
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

/// True when `text` mentions "issue" followed by a number ("issue 12", "issue 17's").
fn mentions_an_issue_number(line: &str) -> bool {
    let lower = line.to_lowercase();
    lower.match_indices("issue").any(|(i, _)| {
        let after = lower[i + "issue".len()..].trim_start_matches([' ', '#']);
        after.starts_with(|c: char| c.is_ascii_digit())
    })
}

#[test]
fn user_docs_name_no_issue_numbers() {
    assert!(mentions_an_issue_number("after the fix (issue 17, below)"));
    assert!(mentions_an_issue_number("see Issue #3"));
    assert!(!mentions_an_issue_number("the issue's targets hold"));
    let mut found = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for (n, line) in text.lines().enumerate() {
            if mentions_an_issue_number(line) {
                found.push(format!("{}:{}: {line}", page.display(), n + 1));
            }
        }
    }
    assert!(
        found.is_empty(),
        "issue numbers in user docs:\n{}",
        found.join("\n")
    );
}
