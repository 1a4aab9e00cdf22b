//! The architecture's layering, checked on the sources: the workspace's crates depend only on
//! crates below them; voyage-core depends on no file-format, codec, image, GPU or GUI crate;
//! and inside it every module imports only modules that come before it in the order the CT
//! goes through `prepare` (no cycles, nothing climbs back up); no two files of any crate
//! import each other, round a circle or directly. And ARCHITECTURE.md, the map, names every
//! source file and nothing that is not there.

use std::{collections::BTreeSet, path::Path};

/// voyage-core's top-level modules, each after everything it may use.
const ORDER: [&str; 17] = [
    "error",
    "rng",
    "volume",
    "simd",
    "mem",
    "grid",
    "anatomy",
    "storage",
    "distance",
    "segment",
    "cleanse",
    "surface",
    "centerline",
    "contacts",
    "cells",
    "navigable",
    "prep",
];

/// The only crates voyage-core may depend on (not dev-dependencies).
const ALLOWED_DEPENDENCIES: [&str; 4] = ["glam", "thiserror", "serde", "rayon"];

fn src() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/src"))
}

/// The source files of a top-level module (`name.rs`, or every file under `name/`).
fn files_of(module: &str) -> Vec<std::path::PathBuf> {
    let file = src().join(format!("{module}.rs"));
    if file.exists() {
        return vec![file];
    }
    let mut out = Vec::new();
    let mut stack = vec![src().join(module)];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out
}

/// The top-level modules `text` names through `crate::` (its unit tests and comments left out).
fn uses(text: &str) -> BTreeSet<String> {
    let code = match text.find("#[cfg(test)]\nmod tests") {
        Some(t) => &text[..t],
        None => text,
    };
    let code: String = code
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let mut out = BTreeSet::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // `use crate::{a::X, b, c::{...}}`: the first name of every item of the group.
            let end = group.find("};").unwrap_or(group.len());
            let mut depth = 0;
            let mut item_start = true;
            let mut name = String::new();
            for ch in group[..end].chars() {
                match ch {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        if !name.is_empty() {
                            out.insert(std::mem::take(&mut name));
                        }
                        item_start = true;
                    }
                    c if item_start && (c.is_alphanumeric() || c == '_') => name.push(c),
                    _ if item_start && !name.is_empty() => {
                        out.insert(std::mem::take(&mut name));
                        item_start = false;
                    }
                    _ => {}
                }
            }
            if !name.is_empty() {
                out.insert(name);
            }
        } else {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            out.insert(name);
        }
    }
    out
}

#[test]
fn modules_only_use_modules_before_them() {
    let mut seen = BTreeSet::new();
    for (rank, module) in ORDER.iter().enumerate() {
        let files = files_of(module);
        assert!(!files.is_empty(), "module {module} not found");
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap();
            for used in uses(&text) {
                let Some(r) = ORDER.iter().position(|m| *m == used) else {
                    continue; // a re-exported name at the crate root (Error, Volume ...)
                };
                assert!(
                    r <= rank,
                    "{} uses crate::{used}, which comes after {module} in the pipeline",
                    file.display()
                );
            }
        }
        seen.insert(*module);
    }
    // Every module of lib.rs is in the order.
    let lib = std::fs::read_to_string(src().join("lib.rs")).unwrap();
    for line in lib.lines() {
        let line = line.trim_start_matches("pub ");
        if let Some(name) = line.strip_prefix("mod ") {
            let name = name.trim_end_matches(';');
            assert!(
                seen.contains(name),
                "lib.rs has module {name}, not in ORDER"
            );
        }
    }
}

#[test]
fn depends_on_no_file_format_or_gui_crate() {
    let manifest =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml")).unwrap();
    for name in dependencies(&manifest) {
        assert!(
            ALLOWED_DEPENDENCIES.contains(&name.as_str()),
            "voyage-core depends on {name} (allowed: {ALLOWED_DEPENDENCIES:?})"
        );
    }
}

/// The workspace's crates, each above every crate it may depend on.
/// voyage-io (loaders and writers) sits below navigation and views, so that the loaders, their
/// fuzz targets and voyage-core's tests compile none of them; voyage-export sits above both.
const CRATES: [&str; 8] = [
    "voyage-core",
    "voyage-phantom",
    "voyage-io",
    "voyage-nav",
    "voyage-view",
    "voyage-export",
    "voyage-render",
    "voyage",
];

/// The names under a manifest's normal dependency sections.
fn dependencies(manifest: &str) -> Vec<String> {
    let mut section = "";
    let mut out = Vec::new();
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            section = line;
            continue;
        }
        let normal = section == "[dependencies]" || section.ends_with(".dependencies]");
        if normal && !line.is_empty() && !line.starts_with('#') {
            out.push(line.split(['=', '.']).next().unwrap().trim().to_string());
        }
    }
    out
}

#[test]
fn crates_depend_only_on_crates_below_them() {
    let crates = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    for (rank, name) in CRATES.iter().enumerate() {
        let manifest = std::fs::read_to_string(crates.join(name).join("Cargo.toml")).unwrap();
        for dep in dependencies(&manifest) {
            if let Some(r) = CRATES.iter().position(|c| *c == dep) {
                assert!(r < rank, "{name} depends on {dep}, which is not below it");
            }
        }
    }
}

#[test]
fn the_checker_sees_grouped_and_plain_uses() {
    let text = "use crate::{\n    Error, Volume,\n    grid::{BoxGrid, Padded},\n    distance::geodesic::X,\n};\nfn f() { crate::mem::filled(1, 0); }\n";
    let got = uses(text);
    for want in ["grid", "distance", "mem", "Error", "Volume"] {
        assert!(got.contains(want), "{want} not in {got:?}");
    }
}

/// The window reaches nothing of the command line: what both need (opening a study, the
/// user's points) lives in the binary's `open` module, image writing in voyage-io.
#[test]
fn the_window_imports_nothing_from_the_commands() {
    let gui = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../voyage/src/gui"));
    let mut checked = 0;
    for entry in std::fs::read_dir(gui).unwrap_or_else(|e| panic!("{}: {e}", gui.display())) {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let used = uses(&text);
        assert!(!used.contains("cmd"), "{} uses crate::cmd", path.display());
        checked += 1;
    }
    assert!(
        checked >= 10,
        "only {checked} files under {}",
        gui.display()
    );
}

/// The repository's root.
fn repo() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every file under `dir` (recursively) whose name ends with one of `exts`.
fn files_under(dir: &Path, exts: &[&str]) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if exts.iter().any(|e| path.to_string_lossy().ends_with(e)) {
                out.push(path);
            }
        }
    }
    out
}

/// ARCHITECTURE.md's section for each crate (`### \`name\`` up to the next heading).
fn map_sections(map: &str) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = Vec::new();
    for line in map.lines() {
        if line.starts_with('#') {
            let name = line
                .strip_prefix("### `")
                .and_then(|rest| rest.split('`').next())
                .filter(|n| n.starts_with("voyage"));
            if let Some(n) = name {
                out.push((n.to_string(), String::new()));
                continue;
            }
            out.push((String::new(), String::new()));
        } else if let Some(last) = out.last_mut() {
            last.1.push_str(line);
            last.1.push('\n');
        }
    }
    out.retain(|(n, _)| !n.is_empty());
    out
}

/// The paths `text` names: words ending in a source or script extension, or in `/` (a
/// folder), inside backticks or not.
fn named_paths(text: &str) -> Vec<String> {
    let exts = [".rs", ".wgsl", ".sh", ".patch", ".toml", ".py"];
    text.split(|c: char| !(c.is_ascii_alphanumeric() || "_./-".contains(c)))
        .map(|w| w.trim_start_matches("./").trim_end_matches('.'))
        .filter(|w| exts.iter().any(|e| w.ends_with(e)) || (w.ends_with('/') && w.len() > 1))
        .map(str::to_string)
        .collect()
}

/// ARCHITECTURE.md is a true map: every source file of every crate is named in its crate's
/// section (by its path under `src/`, its file name, or a folder it sits in), and every path
/// the map names exists.
#[test]
fn the_map_names_every_source_file_and_every_path_it_names_exists() {
    let root = repo();
    let map = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let sections = map_sections(&map);
    let crates: Vec<String> = std::fs::read_dir(root.join("crates"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let mut unnamed = Vec::new();
    for krate in &crates {
        let text = sections
            .iter()
            .find(|(n, _)| n == krate)
            .map(|(_, t)| t.as_str())
            .unwrap_or_else(|| panic!("ARCHITECTURE.md has no section for {krate}"));
        let names = named_paths(text);
        let src = root.join("crates").join(krate).join("src");
        for file in files_under(&src, &[".rs", ".wgsl"]) {
            let rel = file
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let base = rel.rsplit('/').next().unwrap().to_string();
            let root_file = rel == "lib.rs" || rel == "main.rs";
            let in_named_folder = names
                .iter()
                .any(|n| n.ends_with('/') && rel.starts_with(n.as_str()));
            let named = names.iter().any(|n| *n == rel || *n == base);
            if !(root_file || named || in_named_folder) {
                unnamed.push(format!("crates/{krate}/src/{rel}"));
            }
        }
    }
    assert!(
        unnamed.is_empty(),
        "source files ARCHITECTURE.md does not name: {unnamed:?}"
    );
    // Every path named exists: from the root, under a crate, or as the end of a source
    // file's or test's path.
    let everything: Vec<String> = files_under(&root.join("crates"), &[""])
        .iter()
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .collect();
    let missing: Vec<String> = named_paths(&map)
        .into_iter()
        .filter(|n| {
            let folder = n.trim_end_matches('/');
            !(root.join(n).exists()
                || crates
                    .iter()
                    .any(|c| root.join("crates").join(c).join(n).exists())
                || everything
                    .iter()
                    .any(|p| p.ends_with(&format!("/{n}")) || p.contains(&format!("/{folder}/"))))
        })
        .collect();
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names paths that do not exist: {missing:?}"
    );
}

/// The module path of a source file under a crate's `src` (`segment/mod.rs` → `segment`,
/// `segment/runs.rs` → `segment::runs`; the crate root → empty).
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .trim_end_matches(".rs")
        .split('/')
        .map(str::to_string)
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The first-level paths a `use` tree names: `a::{b, c::{d}}` → `a::b`, `a::c::d`.
fn use_paths(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        return vec![tree.split(" as ").next().unwrap_or("").trim().to_string()];
    };
    let prefix = tree[..open].trim();
    let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
    let (mut depth, mut start, mut out) = (0, 0, Vec::new());
    for (i, c) in inner.char_indices().chain([(inner.len(), ',')]) {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                let part = inner[start..i].trim();
                if !part.is_empty() {
                    out.extend(use_paths(part).into_iter().map(|p| {
                        if p == "self" {
                            prefix.trim_end_matches("::").to_string()
                        } else {
                            format!("{prefix}{p}")
                        }
                    }));
                }
                start = i + 1;
            }
            _ => {}
        }
    }
    out
}

/// No two source files import each other, directly or round a circle (a crate's root,
/// which re-exports, left out): each file's `use` lines resolved to the file of the module
/// they name, or of the module that holds the item they name.
#[test]
fn no_circle_between_files() {
    let root = repo();
    let mut circles = Vec::new();
    for entry in std::fs::read_dir(root.join("crates")).unwrap() {
        let src = entry.unwrap().path().join("src");
        let files: Vec<(Vec<String>, String)> = files_under(&src, &[".rs"])
            .into_iter()
            .map(|f| {
                let rel = f
                    .strip_prefix(&src)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/");
                (module_of(&rel), std::fs::read_to_string(&f).unwrap())
            })
            .filter(|(m, _)| !m.is_empty())
            .collect();
        let index = |m: &[String]| files.iter().position(|(fm, _)| fm.as_slice() == m);
        let mut edges: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); files.len()];
        for (i, (module, text)) in files.iter().enumerate() {
            let code = text.split("#[cfg(test)]").next().unwrap_or("");
            for stmt in code
                .split(';')
                .filter_map(|s| s.trim().strip_prefix("use "))
            {
                let stmt = stmt.trim_start_matches("pub ");
                for path in use_paths(stmt) {
                    let segs: Vec<&str> = path.split("::").collect();
                    // `super` of `a::b` (a/b.rs) is `a`; of `a` (a/mod.rs) the root.
                    let mut base: Vec<String> = match segs[0] {
                        "crate" => Vec::new(),
                        "super" => module[..module.len() - 1].to_vec(),
                        "self" => module.clone(),
                        _ => continue,
                    };
                    // The deepest module of the path that is a file of this crate.
                    let mut target = None;
                    for s in &segs[1..] {
                        base.push(s.to_string());
                        match index(&base) {
                            Some(t) => target = Some(t),
                            None => break,
                        }
                    }
                    let target = target.or_else(|| {
                        base.truncate(base.len().saturating_sub(1));
                        index(&base)
                    });
                    if let Some(t) = target.filter(|&t| t != i) {
                        edges[i].insert(t);
                    }
                }
            }
        }
        // A circle: a file that reaches itself.
        for start in 0..files.len() {
            let mut seen = vec![false; files.len()];
            let mut stack: Vec<usize> = edges[start].iter().copied().collect();
            while let Some(f) = stack.pop() {
                if f == start {
                    let krate = src.parent().and_then(|c| c.file_name()).unwrap_or_default();
                    circles.push(format!(
                        "{}: {}",
                        krate.to_string_lossy(),
                        files[start].0.join("::")
                    ));
                    break;
                }
                if !std::mem::replace(&mut seen[f], true) {
                    stack.extend(edges[f].iter().copied());
                }
            }
        }
    }
    assert!(
        circles.is_empty(),
        "files in a circle of imports: {circles:?}"
    );
}
