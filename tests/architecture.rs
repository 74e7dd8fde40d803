//! The layout is the architecture: two crates, the library (`src/`) and the lab (`lab/src/`:
//! the studies and the command line), which the library cannot import (cargo refuses a
//! dependency cycle). In each, no module imports one that imports it back, and every module
//! imports from its own layer or those above it; the bottom layer (`core`) imports nothing
//! else of the library. Read from the source text: every `crate::`, `super::` and `self::`
//! path (each item of a brace group) outside comments and test modules is an import of the
//! module it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Every `.rs` file below `src`.
fn rs_files_in(src: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files
}

/// The library's sources (`src/`).
fn library() -> std::path::PathBuf {
    selfmodel_lab::workspace().join("src")
}

/// The lab's sources (`lab/src/`).
fn lab() -> std::path::PathBuf {
    selfmodel_lab::workspace().join("lab/src")
}

/// The paths a piece of code names from `start` (just past `crate::`, `super::` or `self::`):
/// `a::b`, or each item of a brace group `a::{b::C, d}` (one level: `a::b::C`, `a::d`).
fn named_paths(rest: &str) -> Vec<String> {
    let is_path = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':';
    let end = rest.find(|c: char| !is_path(c)).unwrap_or(rest.len());
    let head = rest[..end].trim_end_matches(':');
    if !rest[end..].starts_with('{') {
        return vec![head.to_string()];
    }
    let Some(close) = rest[end..].find('}') else {
        return vec![head.to_string()];
    };
    let items = &rest[end + 1..end + close];
    let mut out: Vec<String> = items
        .split(',')
        .map(|item| {
            let item: String = item.chars().filter(|c| !c.is_whitespace()).collect();
            item.split('{')
                .next()
                .unwrap_or("")
                .trim_end_matches(':')
                .to_string()
        })
        // `self` in a group is the head; a trailing comma leaves an empty item.
        .filter(|item| !item.is_empty() && item != "self")
        .map(|item| match head.is_empty() {
            true => item,
            false => format!("{head}::{item}"),
        })
        .collect();
    if out.is_empty() {
        out.push(head.to_string());
    }
    out
}

/// Module path (`sim::kinematics`) -> the modules it refers to, for the tree at `src`: every
/// `crate::`, `super::` and `self::` path outside comments and test modules.
fn import_graph_of(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    for path in rs_files_in(src) {
        let rel = path.strip_prefix(src).unwrap().with_extension("");
        let module = rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect::<Vec<_>>()
            .join("::");
        // A folder's `mod.rs` is the folder's module (`sim::kinematics`).
        let module = module.strip_suffix("::mod").unwrap_or(&module).to_string();
        if module != "lib" {
            files.push((module, path));
        }
    }
    let modules: BTreeSet<String> = files.iter().map(|(m, _)| m.clone()).collect();
    let mut graph = BTreeMap::new();
    for (module, path) in &files {
        let text = std::fs::read_to_string(path).unwrap();
        // Test modules sit at the end of a file; comments name modules without importing them.
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap();
        let code: String = code
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .map(|l| l.to_string() + "\n")
            .collect();
        let own: Vec<&str> = module.split("::").collect();
        let mut refs = BTreeSet::new();
        for prefix in ["crate::", "super::", "self::"] {
            for (i, _) in code.match_indices(prefix) {
                let before = code[..i].chars().next_back();
                if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') {
                    continue;
                }
                // Where the path starts: the crate's root, this module, or its parents.
                let mut rest = &code[i + prefix.len()..];
                let mut base: Vec<&str> = match prefix {
                    "crate::" => Vec::new(),
                    "self::" => own.clone(),
                    _ => own[..own.len() - 1].to_vec(),
                };
                while let Some(r) = rest.strip_prefix("super::") {
                    base.pop();
                    rest = r;
                }
                for named in named_paths(rest) {
                    let mut parts: Vec<&str> = base.clone();
                    parts.extend(named.split("::").filter(|p| !p.is_empty()));
                    // The longest prefix that is a module.
                    if let Some(target) = (1..=parts.len())
                        .rev()
                        .map(|k| parts[..k].join("::"))
                        .find(|p| modules.contains(p))
                        .filter(|t| t != module)
                    {
                        refs.insert(target);
                    }
                }
            }
        }
        graph.insert(module.clone(), refs);
    }
    graph
}

/// [`import_graph_of`] the library's `src/`.
fn import_graph() -> BTreeMap<String, BTreeSet<String>> {
    import_graph_of(&library())
}

/// The import cycles: Tarjan's strongly connected components of more than one module.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in s.graph[v].iter().map(String::as_str) {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack.remove(w);
                component.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.out.push(component);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let graph = import_graph();
    assert!(graph.len() > 50, "found only {} modules", graph.len());
    assert!(
        graph["ik::solve::targets"].contains("sim::robot"),
        "the reader misses imports"
    );
    let found = cycles(&graph);
    assert!(found.is_empty(), "import cycles in the library: {found:?}");
    let lab = import_graph_of(&lab());
    assert!(
        lab.len() > 20,
        "found only {} modules of the lab",
        lab.len()
    );
    assert!(
        lab["studies::table1"].contains("studies::run"),
        "the reader misses the lab's imports"
    );
    let found = cycles(&lab);
    assert!(found.is_empty(), "import cycles in the lab: {found:?}");
}

/// The library is the library: no study, no command line, no allocator chosen for its users.
#[test]
fn the_library_holds_no_study_and_no_command_line() {
    let src = library();
    for gone in ["studies", "studies.rs", "cli.rs"] {
        assert!(!src.join(gone).exists(), "src/{gone} belongs to the lab");
    }
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    assert!(
        !lib.contains("global_allocator"),
        "the library chooses an allocator"
    );
}

/// A user of the library gets no command-line, allocator or plotting crate unless asked: in
/// the library's manifest, clap and the plotting crates are optional (the `clap` and
/// `figures` features, not default ones) and mimalloc is not there.
#[test]
fn the_library_pulls_no_cli_allocator_or_plotting_crate_by_default() {
    let manifest = std::fs::read_to_string(selfmodel_lab::workspace().join("Cargo.toml")).unwrap();
    let section = |name: &str| -> Vec<String> {
        let start = manifest
            .find(&format!("\n[{name}]\n"))
            .unwrap_or_else(|| panic!("no [{name}] in Cargo.toml"));
        manifest[start + name.len() + 4..]
            .lines()
            .take_while(|l| !l.starts_with('['))
            .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty())
            .map(String::from)
            .collect()
    };
    let deps = section("dependencies");
    for krate in ["clap", "plotters", "plotters-backend", "ab_glyph", "image"] {
        let line = deps
            .iter()
            .find(|l| l.starts_with(&format!("{krate} =")))
            .unwrap_or_else(|| panic!("{krate} is not a dependency of the library"));
        assert!(
            line.contains("optional = true"),
            "{krate} is not optional: {line}"
        );
    }
    assert!(
        !deps.iter().any(|l| l.starts_with("mimalloc")),
        "the library depends on mimalloc"
    );
    let default = section("features")
        .into_iter()
        .find(|l| l.starts_with("default ="))
        .expect("default features");
    assert!(
        !default.contains("figures") && !default.contains("clap"),
        "{default}"
    );
}

/// Two files of a folder that import each other through `super::` (and a third through
/// `self::` and a brace group), planted in a tree of their own: the reader sees the cycle.
#[test]
fn a_planted_super_cycle_is_found() {
    let dir = std::env::temp_dir().join(format!("architecture-{}", std::process::id()));
    let folder = dir.join("ik");
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::write(dir.join("ik.rs"), "pub mod a;\npub mod b;\npub mod c;\n").unwrap();
    std::fs::write(folder.join("a.rs"), "use super::b::B;\npub struct A;\n").unwrap();
    std::fs::write(
        folder.join("b.rs"),
        "use super::{\n    a::A,\n    c::C,\n};\npub struct B;\n",
    )
    .unwrap();
    std::fs::write(
        folder.join("c.rs"),
        "pub struct C;\n// super::a::A in a comment\n",
    )
    .unwrap();
    let graph = import_graph_of(&dir);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(graph["ik::b"], ["ik::a", "ik::c"].map(String::from).into());
    assert!(graph["ik::c"].is_empty(), "{graph:?}");
    assert_eq!(cycles(&graph), vec![vec!["ik::a", "ik::b"]]);
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let mut graph = BTreeMap::new();
    let edge = |a: &str, b: &[&str]| (a.to_string(), b.iter().map(|s| s.to_string()).collect());
    graph.extend([
        edge("a", &["b"]),
        edge("b", &["c"]),
        edge("c", &["a"]),
        edge("d", &["a"]),
    ]);
    assert_eq!(cycles(&graph), vec![vec!["a", "b", "c"]]);
}

#[test]
fn core_imports_nothing_above_it() {
    for (module, refs) in import_graph() {
        if module.starts_with("core") {
            let above: Vec<_> = refs.iter().filter(|r| !r.starts_with("core")).collect();
            assert!(above.is_empty(), "{module} imports {above:?}");
        }
    }
}

/// The layers of ARCHITECTURE.md, top to bottom: a module imports from its own layer or the
/// layers above it in this list, never from one below. The library's, then the lab's.
const LAYERS: &[&str] = &[
    "core",
    "sim",
    "data",
    "kernels",
    "train",
    "eval",
    "report",
    "self_models",
    "ik",
    "body",
    "studies",
    "cli",
];

/// Every import of `graph` from a layer below its module's, as "a imports b".
fn upward_imports(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let layer = |module: &str| {
        let top = module.split("::").next().unwrap_or(module);
        LAYERS.iter().position(|l| *l == top)
    };
    let mut wrong = Vec::new();
    for (module, refs) in graph {
        let Some(own) = layer(module) else {
            panic!("{module} is in no layer of ARCHITECTURE.md");
        };
        for r in refs {
            if layer(r).is_some_and(|l| l > own) {
                wrong.push(format!("{module} imports {r}"));
            }
        }
    }
    wrong
}

#[test]
fn every_module_imports_only_its_own_layer_or_those_above_it() {
    let wrong = upward_imports(&import_graph());
    assert!(wrong.is_empty(), "imports from a layer below: {wrong:#?}");
    let wrong = upward_imports(&import_graph_of(&lab()));
    assert!(
        wrong.is_empty(),
        "the lab's imports from a layer below: {wrong:#?}"
    );
}

#[test]
fn the_layer_check_finds_an_import_from_a_layer_below() {
    let mut graph = import_graph();
    graph
        .get_mut("sim::robot")
        .expect("sim::robot is read")
        .insert("ik::solve::targets".to_string());
    assert_eq!(
        upward_imports(&graph),
        vec!["sim::robot imports ik::solve::targets".to_string()]
    );
}

/// Every source file of both crates, as ARCHITECTURE.md names it (`sim/robot.rs`,
/// `studies/run.rs`): all but `lib.rs` and the files that open a folder of the same name
/// (`sim.rs`), which the layer list describes.
fn source_files() -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for src in [library(), lab()] {
        for path in rs_files_in(&src) {
            if path.with_extension("").is_dir() {
                continue;
            }
            let rel = path
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            if rel != "lib.rs" {
                out.insert(rel);
            }
        }
    }
    out
}

#[test]
fn architecture_md_gives_every_source_file_its_role_and_names_no_file_that_is_gone() {
    let text = std::fs::read_to_string(selfmodel_lab::workspace().join("ARCHITECTURE.md")).unwrap();
    // The table rows: "| `sim/robot.rs` | what it is |".
    let listed: BTreeSet<String> = text
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split_once("` |").map(|(path, _)| path.to_string()))
        .filter(|path| path.ends_with(".rs"))
        .collect();
    let files = source_files();
    assert!(files.len() > 100, "found only {} files", files.len());
    let missing: Vec<_> = files.difference(&listed).collect();
    let gone: Vec<_> = listed
        .iter()
        .filter(|f| !library().join(f).is_file() && !lab().join(f).is_file())
        .collect();
    assert!(
        missing.is_empty(),
        "files ARCHITECTURE.md does not describe: {missing:?}"
    );
    assert!(
        gone.is_empty(),
        "ARCHITECTURE.md describes files that are gone: {gone:?}"
    );
}
