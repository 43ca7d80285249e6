//! The shape of the code itself: no function in `crates/*/src` longer than 100 lines; the
//! library's folders in the pipeline's order, each importing only the folders below it (which
//! also rules out any import cycle between them), across the library's crates (each folder in
//! one crate, importing only its own crate's folders and those of the crates it depends on, and
//! the facade `stagerl` re-exporting the lower crates' folders at `stagerl::<folder>`);
//! re-exports only in `lib.rs`; and no import cycle between the command-line tool's commands.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_FN_LINES: usize = 100;

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()) {
        if e.is_dir() {
            rust_files(&e, out);
        } else if e.extension().is_some_and(|x| x == "rs") {
            out.push(e);
        }
    }
}

fn crates_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A line without its string and char literals and its `//` comment, for counting braces.
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                while let Some(d) = chars.next() {
                    match d {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
            }
            '\'' => {
                // A char literal ('x', '\n', '{'); a lifetime ('a) has no closing quote nearby.
                let rest: String = chars.clone().take(4).collect();
                if let Some(end) = rest.find('\'').filter(|&i| i > 0 && i <= 3) {
                    for _ in 0..=end {
                        chars.next();
                    }
                }
            }
            '/' if chars.peek() == Some(&'/') => break,
            _ => out.push(c),
        }
    }
    out
}

/// `(lines, name, first line)` of every function with a body in `text`.
fn functions(text: &str) -> Vec<(usize, String, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut found = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code = code_of(line);
        let Some(at) =
            code.find("fn ").filter(|&k| k == 0 || !code.as_bytes()[k - 1].is_ascii_alphanumeric())
        else {
            continue;
        };
        let name: String = code[at + 3..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if name.is_empty() {
            continue;
        }
        let (mut depth, mut started) = (0i64, false);
        for (j, l) in lines.iter().enumerate().skip(i) {
            let c = code_of(l);
            let from = if j == i { at } else { 0 };
            for ch in c[from..].chars() {
                match ch {
                    '{' => {
                        depth += 1;
                        started = true;
                    }
                    '}' => depth -= 1,
                    ';' if !started => break,
                    _ => {}
                }
            }
            if !started && c[from..].contains(';') {
                break;
            }
            if started && depth <= 0 {
                found.push((j - i + 1, name.clone(), i + 1));
                break;
            }
        }
    }
    found
}

#[test]
fn no_function_longer_than_100_lines() {
    let mut files = Vec::new();
    for krate in std::fs::read_dir(crates_dir()).unwrap().map(|e| e.unwrap().path()) {
        if krate.join("src").is_dir() {
            rust_files(&krate.join("src"), &mut files);
        }
    }
    assert!(files.len() > 20, "found the sources: {files:?}");
    let mut long = Vec::new();
    let mut longest = (0, String::new());
    for f in &files {
        for (n, name, line) in functions(&std::fs::read_to_string(f).unwrap()) {
            let place = format!("{}:{line} {name}", f.display());
            if n > longest.0 {
                longest = (n, place.clone());
            }
            if n > MAX_FN_LINES {
                long.push(format!("{place}: {n} lines"));
            }
        }
    }
    assert!(long.is_empty(), "functions over {MAX_FN_LINES} lines:\n{}", long.join("\n"));
    println!("longest function: {} lines, {}", longest.0, longest.1);
}

#[test]
fn the_counter_sees_function_bodies() {
    let text =
        "fn a() {\n    let s = \"}\";\n    let c = '{';\n}\n\nfn b<'x>(v: &'x str) -> &'x str {\n    v\n}\n\
                trait T {\n    fn c(&self);\n}\n";
    let f = functions(text);
    assert_eq!(f, [(4, "a".to_string(), 1), (3, "b".to_string(), 6)]);
}

/// The library's crates from the bottom up, each with the folders it holds (`src/<folder>/`): a
/// crate depends only on crates before it, and the last, `stagerl`, is the facade that re-exports
/// the folders of the others.
const CRATES: [(&str, &[&str]); 4] = [
    ("stagerl-base", &["base"]),
    ("stagerl-nn", &["nn"]),
    ("stagerl-sim", &["robot", "sim"]),
    (
        "stagerl",
        &[
            "io", "agent", "reward", "env", "config", "run", "train", "plan", "export", "view", "report",
            "sweep",
        ],
    ),
];

/// The crate that holds a folder.
fn crate_of(folder: &str) -> &'static str {
    CRATES.iter().find(|(_, folders)| folders.contains(&folder)).map(|(c, _)| *c).unwrap()
}

/// The library crates `krate`'s Cargo.toml names among its `[dependencies]`.
fn crate_deps(krate: &str) -> BTreeSet<String> {
    let toml = std::fs::read_to_string(crates_dir().join(krate).join("Cargo.toml")).unwrap();
    let mut section = String::new();
    let mut deps = BTreeSet::new();
    for line in toml.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line.to_string();
        } else if section == "[dependencies]" {
            let name = line.split(['.', '=', ' ']).next().unwrap();
            if CRATES.iter().any(|(c, _)| *c == name) {
                deps.insert(name.to_string());
            }
        }
    }
    deps
}

/// The top-level modules each library module (a folder of one of the library's crates) names
/// through `crate::<module>` in its code, or through a lower crate's path (`stagerl_base::...`).
fn module_uses() -> BTreeMap<String, BTreeSet<String>> {
    let mut uses: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (krate, _) in CRATES {
        let src = crates_dir().join(krate).join("src");
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        for f in files {
            let rel = f.strip_prefix(&src).unwrap();
            let top = rel
                .components()
                .next()
                .unwrap()
                .as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string();
            if top == "lib" {
                continue;
            }
            // Code only: a doc link to another module is no dependency.
            let text: String =
                std::fs::read_to_string(&f).unwrap().lines().map(|l| code_of(l) + "\n").collect();
            let edges = uses.entry(top.clone()).or_default();
            for (k, _) in text.match_indices("crate::") {
                let rest = &text[k + "crate::".len()..];
                let names: Vec<&str> = if let Some(group) = rest.strip_prefix('{') {
                    group
                        .split('}')
                        .next()
                        .unwrap()
                        .split(',')
                        .map(|n| n.split("::").next().unwrap().trim())
                        .collect()
                } else {
                    vec![rest.split(|c: char| !(c.is_alphanumeric() || c == '_')).next().unwrap()]
                };
                for n in names {
                    // A folder (not a type, nor a macro at a crate's root such as `multiversion`).
                    let is_folder = CRATES.iter().any(|(_, folders)| folders.contains(&n));
                    if is_folder && n != top {
                        edges.insert(n.to_string());
                    }
                }
            }
            // A lower crate named directly (its macros sit at its root): a use of its folders.
            for (other, folders) in &CRATES[..CRATES.len() - 1] {
                let path = format!("{}::", other.replace('-', "_"));
                for (k, _) in text.match_indices(&path) {
                    let next =
                        text[k + path.len()..].split(|c: char| !(c.is_alphanumeric() || c == '_')).next();
                    let named = folders.iter().find(|f| Some(**f) == next);
                    for f in named.map_or(*folders, std::slice::from_ref) {
                        if *f != top {
                            edges.insert(f.to_string());
                        }
                    }
                }
            }
        }
    }
    uses
}

#[test]
fn no_import_cycle_between_modules() {
    let uses = module_uses();
    assert!(uses.get("train").is_some_and(|u| u.contains("config")), "the scan sees imports: {uses:?}");
    // A cycle exists when some module reaches itself.
    let mut cycles = Vec::new();
    for start in uses.keys() {
        let mut stack: Vec<Vec<&str>> = vec![vec![start.as_str()]];
        let mut seen = BTreeSet::new();
        while let Some(path) = stack.pop() {
            let last = *path.last().unwrap();
            for next in uses.get(last).into_iter().flatten() {
                if next == start {
                    cycles.push(format!("{} -> {start}", path.join(" -> ")));
                } else if seen.insert(next.as_str()) {
                    let mut p = path.clone();
                    p.push(next);
                    stack.push(p);
                }
            }
        }
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

/// The library's folders from the bottom up: each may import only those before it. `nn` and `agent`
/// sit below the arm and the task, so that the learners see arrays only.
const ORDER: [&str; 16] = [
    "base", "nn", "io", "agent", "robot", "sim", "reward", "env", "config", "run", "train", "plan", "export",
    "view", "report", "sweep",
];

/// The folders a crate's `lib.rs` declares (`pub mod` or `mod`).
fn declared_modules(krate: &str) -> BTreeSet<String> {
    let lib = std::fs::read_to_string(crates_dir().join(krate).join("src/lib.rs")).unwrap();
    lib.lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod ").or(l.trim().strip_prefix("mod ")))
        .map(|m| m.trim_end_matches(';').to_string())
        .collect()
}

#[test]
fn folders_import_only_the_folders_below_them() {
    let uses = module_uses();
    let declared: BTreeSet<String> = uses.keys().cloned().collect();
    let ordered: BTreeSet<String> = ORDER.iter().map(|s| s.to_string()).collect();
    assert_eq!(declared, ordered, "the library's top-level modules are the folders of ORDER");
    let held: BTreeSet<String> = CRATES.iter().flat_map(|(_, f)| f.iter().map(|s| s.to_string())).collect();
    assert_eq!(held, ordered, "each folder of ORDER sits in one of CRATES");
    for (krate, folders) in CRATES {
        let own: BTreeSet<String> = folders.iter().map(|s| s.to_string()).collect();
        assert_eq!(declared_modules(krate), own, "{krate}'s lib.rs declares exactly its folders of CRATES");
    }
    let mut wrong = Vec::new();
    for (i, m) in ORDER.iter().enumerate() {
        for used in &uses[*m] {
            match ORDER.iter().position(|o| o == used) {
                Some(j) if j < i => {}
                _ => wrong.push(format!("{m} imports {used}")),
            }
        }
    }
    assert!(
        uses["train"].contains("agent") && uses["agent"].contains("nn") && uses["nn"].contains("base"),
        "the scan sees imports: {uses:?}"
    );
    assert!(wrong.is_empty(), "imports against the pipeline's order:\n{}", wrong.join("\n"));
}

/// The crates' layering: a crate depends only on library crates below it in CRATES, and each
/// folder imports only its own crate's folders and those of the crates its crate depends on
/// (directly: a folder does not reach through a crate's dependency to the crate below it).
#[test]
fn crates_import_only_the_crates_below_them() {
    let uses = module_uses();
    let mut wrong = Vec::new();
    for (i, (krate, folders)) in CRATES.iter().enumerate() {
        let deps = crate_deps(krate);
        let below: BTreeSet<String> = CRATES[..i].iter().map(|(c, _)| c.to_string()).collect();
        for d in deps.difference(&below) {
            wrong.push(format!("crate {krate} depends on {d}, not below it"));
        }
        for folder in *folders {
            for used in &uses[*folder] {
                let c = crate_of(used);
                if c != *krate && !deps.contains(c) {
                    wrong.push(format!("{krate}: {folder} imports {used} of {c}, not a dependency"));
                }
            }
        }
    }
    assert!(crate_deps("stagerl").contains("stagerl-sim"), "the scan sees the crates' dependencies");
    assert!(wrong.is_empty(), "imports against the crates' layering:\n{}", wrong.join("\n"));
}

/// The facade re-exports every lower crate's folders, so that users' paths are `stagerl::<folder>`
/// wherever the folder lives.
#[test]
fn the_facade_re_exports_the_lower_crates_folders() {
    let lib = std::fs::read_to_string(crates_dir().join("stagerl/src/lib.rs")).unwrap();
    let mut missing = Vec::new();
    for (krate, folders) in &CRATES[..CRATES.len() - 1] {
        let name = krate.replace('-', "_");
        for f in *folders {
            let single = format!("pub use {name}::{f};");
            let grouped = lib
                .lines()
                .filter_map(|l| l.trim().strip_prefix(&format!("pub use {name}::{{")))
                .any(|g| g.trim_end_matches("};").split(',').any(|n| n.trim() == *f));
            if !lib.contains(&single) && !grouped {
                missing.push(format!("{name}::{f}"));
            }
        }
    }
    assert!(missing.is_empty(), "stagerl's lib.rs does not re-export: {missing:?}");
}

#[test]
fn re_exports_only_in_lib_rs() {
    let mut files = Vec::new();
    for (krate, _) in CRATES {
        rust_files(&crates_dir().join(krate).join("src"), &mut files);
    }
    let offenders: Vec<String> = files
        .iter()
        .filter(|f| !f.ends_with("lib.rs"))
        .filter(|f| {
            std::fs::read_to_string(f)
                .unwrap()
                .lines()
                .any(|l| code_of(l).trim_start().starts_with("pub use crate::"))
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(files.len() > 100, "found the sources: {}", files.len());
    assert!(offenders.is_empty(), "`pub use crate::` outside lib.rs: {offenders:?}");
}

/// The command-line tool's commands: each is flags and wiring, and none imports another (what
/// several share lives beside `cmd/`: run control, progress, output).
#[test]
fn no_command_imports_another() {
    let cmd = crates_dir().join("stagerl-cli/src/cmd");
    let names: Vec<String> = std::fs::read_dir(&cmd)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs") && !p.ends_with("mod.rs"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    assert!(names.len() >= 10 && names.contains(&"train".to_string()), "found the commands: {names:?}");
    let mut wrong = Vec::new();
    for name in &names {
        let text: String = std::fs::read_to_string(cmd.join(format!("{name}.rs")))
            .unwrap()
            .lines()
            .map(|l| code_of(l) + "\n")
            .collect();
        for other in names.iter().filter(|o| *o != name) {
            for path in [format!("super::{other}::"), format!("cmd::{other}::"), format!("super::{{{other}")]
            {
                if text.contains(&path) {
                    wrong.push(format!("{name} uses {path}"));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "commands importing commands:\n{}", wrong.join("\n"));
}

/// One unit-test style: a module's tests sit inline while short, and in a sibling `tests.rs`
/// once they pass about 150 lines.
#[test]
fn long_unit_tests_live_in_their_own_file() {
    let mut files = Vec::new();
    for krate in std::fs::read_dir(crates_dir()).unwrap().map(|e| e.unwrap().path()) {
        if krate.join("src").is_dir() {
            rust_files(&krate.join("src"), &mut files);
        }
    }
    let mut inline = 0;
    let mut long = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (i, l) in lines.iter().enumerate() {
            if l.trim_end().ends_with("mod tests {") && i > 0 && lines[i - 1].trim() == "#[cfg(test)]" {
                inline += 1;
                let end = lines[i..].iter().position(|x| *x == "}").map_or(lines.len(), |p| i + p);
                if end - i > 152 {
                    long.push(format!("{}:{}: {} lines", f.display(), i + 1, end - i));
                }
            }
        }
    }
    assert!(inline > 20, "found the inline test modules: {inline}");
    assert!(
        long.is_empty(),
        "inline test modules over 150 lines (move them to a sibling tests.rs):\n{}",
        long.join("\n")
    );
}
