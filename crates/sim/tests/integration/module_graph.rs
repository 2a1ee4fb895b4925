//! The modules of `accd-sim`, and those of `accd-tether` below it, import each other without a circle: every `crate::` path outside
//! comments and test modules is an edge to the module it names (`crate::config` to `config`,
//! `crate::physics::wake::Wake` to `physics::wake`), and a depth-first search finds no cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module name -> the modules its production code refers to, for the crate whose sources are in
/// `src` (files in `src` and in its folders; a folder's `mod.rs` is the folder's module).
fn graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(src).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            let folder = path.file_name().unwrap().to_str().unwrap().to_string();
            for inner in std::fs::read_dir(&path).unwrap() {
                files.push((Some(folder.clone()), inner.unwrap().path()));
            }
        } else {
            files.push((None, path));
        }
    }
    let mut graph = BTreeMap::new();
    for (folder, path) in files {
        if path.extension().and_then(|e| e.to_str()) != Some("rs") {
            continue;
        }
        let stem = path.file_stem().unwrap().to_str().unwrap().to_string();
        let name = match folder {
            Some(folder) if stem == "mod" => folder,
            Some(folder) => format!("{folder}::{stem}"),
            None => stem,
        };
        let text = std::fs::read_to_string(&path).unwrap();
        let mut deps = BTreeSet::new();
        for line in text.lines() {
            let line = line.trim();
            if line.starts_with("#[cfg(test)]") {
                break; // the test module is at the end of each file
            }
            if line.starts_with("//") {
                continue;
            }
            let mut rest = line;
            while let Some(at) = rest.find("crate::") {
                rest = &rest[at + "crate::".len()..];
                let module = ident(rest);
                let mut target = module.to_string();
                let after = &rest[module.len()..];
                if src.join(module).is_dir() {
                    // A folder with a file module beside it (`dynamics.rs` and `dynamics/`) is
                    // that module's children; a group of items is the file module's own.
                    let has_file = src.join(format!("{module}.rs")).is_file();
                    assert!(
                        has_file || !after.starts_with("::{"),
                        "{}: write one `use` per module of a folder: {line}",
                        path.display()
                    );
                    if let Some(inner) = after.strip_prefix("::") {
                        let inner = ident(inner);
                        if src.join(module).join(format!("{inner}.rs")).is_file() {
                            target = format!("{module}::{inner}");
                        }
                    }
                }
                if !module.is_empty() && target != name {
                    deps.insert(target);
                }
            }
        }
        graph.insert(name, deps);
    }
    graph
}

/// The identifier at the start of `text`.
fn ident(text: &str) -> &str {
    let end = text
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(text.len());
    &text[..end]
}

fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(node.to_string(), 1);
        stack.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if !graph.contains_key(next) {
                continue;
            }
            match state.get(next.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = stack.iter().position(|n| n == next).unwrap();
                    let mut cycle = stack[start..].to_vec();
                    cycle.push(next.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(next, graph, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(node.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for node in graph.keys() {
        if state.get(node.as_str()).copied().unwrap_or(0) == 0 {
            if let Some(c) = visit(node, graph, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

#[test]
fn the_module_graph_has_no_cycle() {
    let graph = graph(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(graph["physics::capture"].contains("physics::wake_field"));
    assert!(graph["task::episode"].contains("physics::capture"));
    assert!(graph["task::config"].contains("config"));
    if let Some(cycle) = find_cycle(&graph) {
        panic!("import cycle: {}", cycle.join(" -> "));
    }
}

#[test]
fn the_tether_module_graph_has_no_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tether/src");
    let graph = graph(&src);
    assert!(graph["dynamics"].contains("recursive"));
    assert!(graph["presets"].contains("material"));
    if let Some(cycle) = find_cycle(&graph) {
        panic!("import cycle in accd-tether: {}", cycle.join(" -> "));
    }
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let mut graph = BTreeMap::new();
    graph.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    graph.insert("b".to_string(), BTreeSet::from(["c".to_string()]));
    graph.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(find_cycle(&graph).unwrap(), ["a", "b", "c", "a"]);
}

/// A cycle through a folder is found: `top` uses `crate::folder::inner`, which uses `crate::top`;
/// the same references in comments and in the test module are no edges.
#[test]
fn a_cycle_through_a_folder_is_found() {
    let src = std::env::temp_dir().join(format!("accd_module_graph_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&src);
    std::fs::create_dir_all(src.join("folder")).unwrap();
    std::fs::write(src.join("lib.rs"), "pub mod folder;\npub mod top;\n").unwrap();
    std::fs::write(src.join("folder/mod.rs"), "pub mod inner;\n").unwrap();
    std::fs::write(
        src.join("top.rs"),
        "use crate::folder::inner::Thing;\n#[cfg(test)]\nuse crate::lib;\n",
    )
    .unwrap();
    let inner = src.join("folder/inner.rs");
    std::fs::write(&inner, "// crate::top in a comment\npub struct Thing;\n").unwrap();
    let acyclic = graph(&src);
    assert_eq!(
        acyclic["top"],
        BTreeSet::from(["folder::inner".to_string()])
    );
    assert_eq!(find_cycle(&acyclic), None);
    std::fs::write(&inner, "use crate::top::Other;\npub struct Thing;\n").unwrap();
    let cycle = find_cycle(&graph(&src));
    std::fs::remove_dir_all(&src).unwrap();
    assert_eq!(
        cycle.unwrap(),
        ["folder::inner", "top", "folder::inner"],
        "the cycle top -> folder::inner -> top"
    );
}
