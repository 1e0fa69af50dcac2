//! The architecture invariants of `docs/ARCHITECTURE.md`, checked on the workspace itself:
//! the crate graph (from `cargo metadata`), and the library sources (parsed with `syn`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// The library crates: engine and building blocks (the application `bamudi-gate`, `xtask`
/// and the test and bench crates are not libraries in this sense).
const LIBRARIES: [&str; 7] = [
    "numerics",
    "orthopoly",
    "gp",
    "seqnet",
    "mlmodel",
    "mitergate",
    "bamudi",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `cargo metadata` of the workspace for this machine's platform (read once).
fn metadata() -> &'static serde_json::Value {
    static META: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
    META.get_or_init(|| {
        let rustc = std::process::Command::new("rustc").arg("-vV").output();
        let info = String::from_utf8(rustc.expect("rustc -vV runs").stdout).unwrap();
        let host = info
            .lines()
            .find_map(|l| l.strip_prefix("host: "))
            .unwrap()
            .to_string();
        let out = std::process::Command::new(env!("CARGO"))
            .args([
                "metadata",
                "--format-version",
                "1",
                "--filter-platform",
                &host,
            ])
            .current_dir(root())
            .output()
            .expect("cargo metadata runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).expect("cargo metadata is JSON")
    })
}

/// Package name of every package id, and the dependency edges (all kinds) of the resolve.
fn graph(meta: &serde_json::Value) -> (BTreeMap<String, String>, BTreeMap<String, Vec<String>>) {
    let names = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["id"].as_str().unwrap().to_string(),
                p["name"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let edges = meta["resolve"]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            let deps = n["deps"].as_array().unwrap().iter();
            let ids = deps
                .map(|d| d["pkg"].as_str().unwrap().to_string())
                .collect();
            (n["id"].as_str().unwrap().to_string(), ids)
        })
        .collect();
    (names, edges)
}

/// Names of every package `name` depends on, directly or not (normal, build and dev edges of
/// `name` itself; normal and build edges below it, as cargo resolves them).
fn closure(meta: &serde_json::Value, name: &str) -> BTreeSet<String> {
    let (names, edges) = graph(meta);
    let start = names
        .iter()
        .find(|(_, n)| n.as_str() == name)
        .unwrap()
        .0
        .clone();
    let (mut seen, mut todo) = (BTreeSet::new(), vec![start]);
    while let Some(id) = todo.pop() {
        for d in edges.get(&id).into_iter().flatten() {
            if seen.insert(d.clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen.into_iter().map(|id| names[&id].clone()).collect()
}

/// Architecture Invariant: the engine never depends on the gate, a command-line parser, a
/// plotting library or a progress-bar library.
#[test]
fn the_engine_knows_no_gate_no_cli_and_no_plots() {
    let deps = closure(metadata(), "bamudi");
    for banned in ["mitergate", "bamudi-gate", "clap", "plotters", "indicatif"] {
        assert!(!deps.contains(banned), "bamudi depends on {banned}");
    }
    for needed in [
        "orthopoly",
        "gp",
        "seqnet",
        "mlmodel",
        "numerics",
        "ndarray",
        "smartcore",
    ] {
        assert!(deps.contains(needed), "bamudi should use {needed}");
    }
}

/// Architecture Invariant: the building blocks depend on nothing above them (orthopoly,
/// numerics < gp, seqnet, mlmodel < mitergate, bamudi < bamudi-gate < xtask).
#[test]
fn building_blocks_depend_only_downwards() {
    let meta = metadata();
    let above: BTreeMap<&str, &[&str]> = BTreeMap::from([
        (
            "numerics",
            &[
                "gp",
                "seqnet",
                "mlmodel",
                "mitergate",
                "bamudi",
                "bamudi-gate",
            ][..],
        ),
        (
            "orthopoly",
            &[
                "gp",
                "seqnet",
                "mlmodel",
                "mitergate",
                "bamudi",
                "bamudi-gate",
            ][..],
        ),
        ("gp", &["mlmodel", "mitergate", "bamudi", "bamudi-gate"][..]),
        (
            "seqnet",
            &["mlmodel", "mitergate", "bamudi", "bamudi-gate"][..],
        ),
        ("mlmodel", &["mitergate", "bamudi", "bamudi-gate"][..]),
        ("mitergate", &["bamudi", "bamudi-gate"][..]),
    ]);
    for (krate, banned) in above {
        let deps = closure(meta, krate);
        for b in banned {
            assert!(!deps.contains(*b), "{krate} depends on {b}");
        }
    }
}

/// The `.rs` files under `dir`.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.is_dir() {
            out.extend(rust_files(&p));
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
    out.sort();
    out
}

fn parse(path: &Path) -> syn::File {
    let text = std::fs::read_to_string(path).unwrap();
    syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Whether an item carries `#[cfg(test)]` (or a `cfg` mentioning `test`).
fn is_test_only(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.meta
                .require_list()
                .is_ok_and(|l| l.tokens.to_string().contains("test"))
    })
}

/// Collects macro names and function lengths outside test-only code.
#[derive(Default)]
struct Scan {
    macros: Vec<String>,
    long_fns: Vec<(String, usize)>,
}

impl Scan {
    fn fn_len(&mut self, name: &syn::Ident, block: &syn::Block) {
        use syn::spanned::Spanned;
        let span = block.span();
        let (start, end): (proc_macro2::LineColumn, proc_macro2::LineColumn) =
            (span.start(), span.end());
        let lines = end.line - start.line + 1;
        if lines > 80 {
            self.long_fns.push((name.to_string(), lines));
        }
    }
}

impl<'a> Visit<'a> for Scan {
    fn visit_item_mod(&mut self, m: &'a syn::ItemMod) {
        if !is_test_only(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_item_fn(&mut self, f: &'a syn::ItemFn) {
        if !is_test_only(&f.attrs) {
            self.fn_len(&f.sig.ident, &f.block);
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_impl_item_fn(&mut self, f: &'a syn::ImplItemFn) {
        if !is_test_only(&f.attrs) {
            self.fn_len(&f.sig.ident, &f.block);
            syn::visit::visit_impl_item_fn(self, f);
        }
    }
    fn visit_macro(&mut self, m: &'a syn::Macro) {
        if let Some(seg) = m.path.segments.last() {
            self.macros.push(seg.ident.to_string());
        }
        syn::visit::visit_macro(self, m);
    }
}

fn scan_library(krate: &str) -> Vec<(PathBuf, Scan)> {
    let src = root().join("crates").join(krate).join("src");
    rust_files(&src)
        .into_iter()
        .map(|p| {
            let mut s = Scan::default();
            s.visit_file(&parse(&p));
            (p, s)
        })
        .collect()
}

/// Architecture Invariant: library crates never print; they report through an observer or
/// the `log` facade.
#[test]
fn library_crates_never_print() {
    let printing = ["println", "eprintln", "print", "eprint", "dbg"];
    for krate in LIBRARIES {
        for (path, scan) in scan_library(krate) {
            let found: Vec<&String> = scan
                .macros
                .iter()
                .filter(|m| printing.contains(&m.as_str()))
                .collect();
            assert!(found.is_empty(), "{} prints: {found:?}", path.display());
        }
    }
}

/// Architecture Invariant: no library function is longer than 80 lines (a house a reader
/// reads top-down).
#[test]
fn library_functions_are_short() {
    let mut long = Vec::new();
    for krate in LIBRARIES.iter().chain(&["bamudi-gate"]) {
        for (path, scan) in scan_library(krate) {
            for (name, lines) in scan.long_fns {
                long.push(format!("{}: {name} ({lines} lines)", path.display()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over 80 lines:\n{}",
        long.join("\n")
    );
}

/// Whether a type mentions a `faer` path or one of faer's matrix types.
fn mentions_faer(ty: &str) -> bool {
    ty.contains("faer")
        || ["Mat <", "MatRef", "MatMut", "Par ::", ": Par", "Par )"]
            .iter()
            .any(|t| ty.contains(t))
}

/// Public signatures (functions, methods, fields) that mention faer.
#[derive(Default)]
struct PublicFaer(Vec<String>);

impl<'a> Visit<'a> for PublicFaer {
    fn visit_item_mod(&mut self, m: &'a syn::ItemMod) {
        if !is_test_only(&m.attrs) && matches!(m.vis, syn::Visibility::Public(_)) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_signature(&mut self, s: &'a syn::Signature) {
        let text = quote_signature(s);
        if mentions_faer(&text) {
            self.0.push(text);
        }
    }
    fn visit_item_fn(&mut self, f: &'a syn::ItemFn) {
        if matches!(f.vis, syn::Visibility::Public(_)) {
            self.visit_signature(&f.sig);
        }
    }
    fn visit_impl_item_fn(&mut self, f: &'a syn::ImplItemFn) {
        if matches!(f.vis, syn::Visibility::Public(_)) {
            self.visit_signature(&f.sig);
        }
    }
    fn visit_field(&mut self, f: &'a syn::Field) {
        let ty = &f.ty;
        let text = quote::quote!(#ty).to_string();
        if matches!(f.vis, syn::Visibility::Public(_)) && mentions_faer(&text) {
            self.0.push(text);
        }
    }
    fn visit_item_use(&mut self, u: &'a syn::ItemUse) {
        let text = quote::quote!(#u).to_string();
        if matches!(u.vis, syn::Visibility::Public(_)) && text.contains("faer") {
            self.0.push(text);
        }
    }
}

fn quote_signature(s: &syn::Signature) -> String {
    quote::quote!(#s).to_string()
}

/// The files of a crate's public modules: from `src/lib.rs`, every `pub mod name;` followed
/// to `name.rs` or `name/mod.rs` (private modules are not public API).
fn public_module_files(src: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut todo = vec![(src.join("lib.rs"), src.to_path_buf())];
    while let Some((file, dir)) = todo.pop() {
        for item in parse(&file).items {
            let syn::Item::Mod(m) = item else { continue };
            if !matches!(m.vis, syn::Visibility::Public(_))
                || m.content.is_some()
                || is_test_only(&m.attrs)
            {
                continue;
            }
            let name = m.ident.to_string();
            let (flat, nested) = (
                dir.join(format!("{name}.rs")),
                dir.join(&name).join("mod.rs"),
            );
            let child = if flat.exists() { flat } else { nested };
            todo.push((child, dir.join(&name)));
        }
        out.push(file);
    }
    out
}

/// Architecture Invariant: public matrices are nalgebra; `faer` types cross a crate boundary
/// only in `numerics`' in-place Cholesky kernel (the faer pattern: an owned API over an
/// in-place kernel with scratch).
#[test]
fn faer_stays_out_of_public_apis() {
    for krate in LIBRARIES.iter().filter(|k| **k != "numerics") {
        for path in public_module_files(&root().join("crates").join(krate).join("src")) {
            let mut v = PublicFaer::default();
            v.visit_file(&parse(&path));
            assert!(
                v.0.is_empty(),
                "{}: public faer types: {:?}",
                path.display(),
                v.0
            );
        }
    }
}

/// Architecture Invariant: each library crate has exactly one error enum, derived with
/// `thiserror`.
#[test]
fn one_error_enum_per_library() {
    for krate in LIBRARIES {
        let mut count = 0;
        for path in rust_files(&root().join("crates").join(krate).join("src")) {
            let text = std::fs::read_to_string(&path).unwrap();
            count += text.matches("thiserror::Error").count();
        }
        assert_eq!(count, 1, "{krate}: {count} thiserror enums");
    }
}

/// The text of `file` and of every file it includes with `#[path = "..."]`.
fn with_path_includes(file: &Path) -> String {
    let text = std::fs::read_to_string(file).unwrap();
    let mut all = text.clone();
    for line in text.lines() {
        let Some(rest) = line.trim().strip_prefix("#[path = \"") else {
            continue;
        };
        let rel = rest.trim_end_matches("\"]");
        if let Ok(t) = std::fs::read_to_string(file.parent().unwrap().join(rel)) {
            all += &t;
        }
    }
    all
}

/// Architecture Invariant: no idle dependency: every `[dependencies]` entry of a workspace
/// crate is used by its sources (library, binaries, examples or build script). A dependency
/// that only enables features of another (none of its paths appear in code) is listed, with
/// the reason, under `[package.metadata.cargo-machete] ignored`, as for `cargo machete`.
#[test]
fn no_dependency_is_idle() {
    let meta = metadata();
    let members: BTreeSet<&str> = meta["workspace_members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap())
        .collect();
    let mut idle = Vec::new();
    for p in meta["packages"].as_array().unwrap() {
        if !members.contains(p["id"].as_str().unwrap()) {
            continue;
        }
        let dir = Path::new(p["manifest_path"].as_str().unwrap())
            .parent()
            .unwrap()
            .to_path_buf();
        let mut text = String::new();
        for sub in ["src", "examples", "benches", "tests", "build.rs"] {
            for f in rust_files(&dir.join(sub)) {
                text += &with_path_includes(&f);
            }
        }
        let ignored: Vec<String> = p["metadata"]["cargo-machete"]["ignored"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|v| v.as_str().map(|s| s.replace('-', "_")))
            .collect();
        for d in p["dependencies"].as_array().unwrap() {
            let kind = d["kind"].as_str();
            let name = d["rename"]
                .as_str()
                .unwrap_or(d["name"].as_str().unwrap())
                .replace('-', "_");
            if (kind.is_some() && kind != Some("dev")) || ignored.contains(&name) {
                continue;
            }
            let used = text.contains(&format!("{name}::"))
                || text.contains(&format!("use {name}"))
                || text.contains(&format!("extern crate {name}"));
            let what = if kind == Some("dev") {
                "dev-dependency"
            } else {
                "dependency"
            };
            if !used {
                idle.push(format!("{}: {what} {name}", p["name"]));
            }
        }
    }
    assert!(
        idle.is_empty(),
        "declared but not used:\n{}",
        idle.join("\n")
    );
}
