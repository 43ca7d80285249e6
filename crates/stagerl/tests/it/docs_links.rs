//! The documentation's references resolve: every relative link of `README.md` and of the
//! Markdown under `docs/` names a file or directory of the repository, and every mention of the
//! design notes in the code names `docs/design.md`, which exists.

use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().unwrap()
}

fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            markdown_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "md") {
            out.push(p);
        }
    }
}

/// The targets of the inline links `[text](target)` of a Markdown text, outside code spans.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_fence = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        // Code spans are not links.
        let code_free: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        let mut rest = code_free.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_of_the_docs_resolves() {
    let root = repo();
    let mut files = vec![root.join("README.md")];
    markdown_files(&root.join("docs"), &mut files);
    assert!(files.len() > 5, "{files:?}");
    let mut broken = Vec::new();
    let mut checked = 0;
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for target in links(&text) {
            let target = target.split_whitespace().next().unwrap_or_default();
            if target.is_empty()
                || target.starts_with('#')
                || target.contains("://")
                || target.starts_with("mailto:")
            {
                continue;
            }
            let path = target.split('#').next().unwrap();
            checked += 1;
            if !f.parent().unwrap().join(path).exists() {
                broken.push(format!("{}: {target}", f.strip_prefix(&root).unwrap().display()));
            }
        }
    }
    assert!(checked > 10, "only {checked} relative links found");
    assert!(broken.is_empty(), "broken relative links:\n{}", broken.join("\n"));
}

#[test]
fn the_link_finder_sees_links_and_skips_code() {
    let md = "a [x](docs/a.md) b `[y](no.md)` c [z](http://e.com)\n```\n[w](no2.md)\n```\n";
    assert_eq!(links(md), vec!["docs/a.md".to_string(), "http://e.com".to_string()]);
}

#[test]
fn the_design_notes_the_code_cites_are_in_the_repository() {
    let root = repo();
    assert!(root.join("docs/design.md").is_file());
    let mut cites = 0;
    let mut stack = vec![root.join("crates")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                let lines: Vec<&str> = text.lines().collect();
                for (i, l) in lines.iter().enumerate() {
                    if l.contains(concat!("design", " notes")) {
                        cites += 1;
                        let near = lines[i..(i + 2).min(lines.len())].join(" ");
                        assert!(near.contains("docs/design.md"), "{}:{}: {l}", p.display(), i + 1);
                    }
                }
            }
        }
    }
    assert!(cites >= 5, "{cites}");
}

fn bytes_under(dir: &Path, largest: &mut Vec<(u64, PathBuf)>) -> u64 {
    let mut total = 0;
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let meta = std::fs::symlink_metadata(&p).unwrap();
        if meta.is_dir() {
            total += bytes_under(&p, largest);
        } else {
            total += meta.len();
            largest.push((meta.len(), p));
        }
    }
    total
}

/// `docs/` stays small enough for every clone (issue 30): under 40 MB, run folders packed into
/// archives (docs/results/README.md, "How results are kept"). On failure it names the largest
/// files.
#[test]
fn the_docs_stay_under_40_mb() {
    let mut largest = Vec::new();
    let total = bytes_under(&repo().join("docs"), &mut largest);
    largest.sort();
    let top: Vec<String> = largest
        .iter()
        .rev()
        .take(5)
        .map(|(n, p)| format!("{} ({:.1} MB)", p.display(), *n as f64 / 1e6))
        .collect();
    assert!(total < 40_000_000, "docs/ holds {:.1} MB (at most 40): largest {top:?}", total as f64 / 1e6);
    assert!(total > 1_000_000, "docs/ read as {total} bytes: not the docs");
}

/// A committed report keeps its figures as SVG only (docs/results/README.md, "How results are
/// kept"): no PNG beside an SVG of the same name under `docs/results/`.
#[test]
fn committed_reports_keep_svg_figures_only() {
    fn walk(dir: &Path, twins: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, twins);
            } else if p.extension().is_some_and(|x| x == "png") && p.with_extension("svg").exists() {
                twins.push(p);
            }
        }
    }
    let mut twins = Vec::new();
    let results = repo().join("docs/results");
    walk(&results, &mut twins);
    assert!(results.join("paper/figure8.svg").exists(), "the paper report's figures are where they were");
    assert!(twins.is_empty(), "PNG twins of SVG figures (delete them): {twins:?}");
}
