//! The layout's promises, read from the sources: no import circle between modules (a module
//! and its own ancestors aside) or between sibling subtrees, and in the core every arrow between
//! stages points down the data flow (`CORE_LAYERS`), so a stage never names one after it.
//!
//! The sources are parsed (`syn`) from each crate root along its `mod` declarations, so every
//! line the compiler builds into the product is read, and nothing else: items under
//! `#[cfg(test)]` (a test module inline or in its own file, a test-only function, import,
//! statement or field) are left out, wherever they sit in the file. Each path is resolved to
//! the module it names: braced imports (`crate::{a::b, c::{d, e}}`) path by path, `super::`,
//! `self::`, a child module's name, a name an import brought in, and paths inside macro
//! arguments.

use proc_macro2::{Spacing, TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
// Raw identifiers (`mod r#move;`) name the module and its file without their `r#`.
use syn::ext::IdentExt;
use syn::visit::{self, Visit};
use syn::{Attribute, Expr, ImplItem, Item, Meta, Stmt, TraitItem, UseTree};

type ModPath = Vec<String>;

/// The core's top-level modules, lowest layer first. A module may use only modules listed
/// before it.
const CORE_LAYERS: &[&str] = &[
    "files",
    "solver",
    "model",
    "plan",
    "trace",
    "bench",
    "hardware",
    "measure",
    "identify",
    "validate",
    "calibration",
    "diagnose",
    "position",
    "session",
    "report",
];

/// One module of a crate as the compiler builds it without tests.
#[derive(Default)]
struct Module {
    /// The file it is read from (an inline module's: the file that holds it).
    file: PathBuf,
    /// Its child modules' names.
    children: BTreeSet<String>,
    /// Names brought in by `use` (the last segment or the `as` name) → the path as written.
    aliases: BTreeMap<String, Vec<String>>,
    /// Every path the module's code writes (imports, types, expressions, macro arguments).
    paths: Vec<Vec<String>>,
}

/// Is this attribute `#[cfg(test)]` or `#[cfg(all(test, …))]`: code compiled only for tests?
fn is_test_cfg(attr: &Attribute) -> bool {
    let Meta::List(list) = &attr.meta else { return false };
    if !list.path.is_ident("cfg") {
        return false;
    }
    let Ok(inner) = list.parse_args::<Meta>() else { return false };
    match inner {
        Meta::Path(p) => p.is_ident("test"),
        Meta::List(all) if all.path.is_ident("all") => all
            .parse_args_with(syn::punctuated::Punctuated::<Meta, syn::Token![,]>::parse_terminated)
            .is_ok_and(|parts| parts.iter().any(|m| m.path().is_ident("test"))),
        _ => false,
    }
}

fn test_only(attrs: &[Attribute]) -> bool {
    attrs.iter().any(is_test_cfg)
}

fn item_attrs(item: &Item) -> &[Attribute] {
    match item {
        Item::Const(i) => &i.attrs,
        Item::Enum(i) => &i.attrs,
        Item::ExternCrate(i) => &i.attrs,
        Item::Fn(i) => &i.attrs,
        Item::ForeignMod(i) => &i.attrs,
        Item::Impl(i) => &i.attrs,
        Item::Macro(i) => &i.attrs,
        Item::Mod(i) => &i.attrs,
        Item::Static(i) => &i.attrs,
        Item::Struct(i) => &i.attrs,
        Item::Trait(i) => &i.attrs,
        Item::TraitAlias(i) => &i.attrs,
        Item::Type(i) => &i.attrs,
        Item::Union(i) => &i.attrs,
        Item::Use(i) => &i.attrs,
        _ => &[],
    }
}

/// The attributes of an expression (`#[cfg(test)] { … }` as a statement).
fn expr_attrs(expr: &Expr) -> &[Attribute] {
    macro_rules! attrs_of {
        ($($v:ident),*) => {
            match expr {
                $(Expr::$v(e) => &e.attrs,)*
                _ => &[],
            }
        };
    }
    attrs_of!(
        Array, Assign, Async, Await, Binary, Block, Break, Call, Cast, Closure, Const, Continue, Field, ForLoop, Group,
        If, Index, Infer, Let, Lit, Loop, Macro, Match, MethodCall, Paren, Path, Range, RawAddr, Reference, Repeat,
        Return, Struct, Try, TryBlock, Tuple, Unary, Unsafe, While, Yield
    )
}

/// Every `a::b::c` sequence in a macro's tokens (macro arguments are not parsed by `syn`).
fn token_paths(tokens: TokenStream, out: &mut Vec<Vec<String>>) {
    let tokens: Vec<TokenTree> = tokens.into_iter().collect();
    let mut i = 0;
    while i < tokens.len() {
        match &tokens[i] {
            TokenTree::Group(g) => token_paths(g.stream(), out),
            TokenTree::Ident(first) => {
                let mut path = vec![first.to_string()];
                let mut j = i + 1;
                while let (Some(TokenTree::Punct(a)), Some(TokenTree::Punct(b)), Some(TokenTree::Ident(next))) =
                    (tokens.get(j), tokens.get(j + 1), tokens.get(j + 2))
                {
                    if a.as_char() != ':' || a.spacing() != Spacing::Joint || b.as_char() != ':' {
                        break;
                    }
                    path.push(next.to_string());
                    j += 3;
                }
                if path.len() > 1 {
                    out.push(path);
                }
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
}

/// Walks one file's syntax tree, skipping what is compiled only for tests.
struct Reader<'a> {
    modules: &'a mut BTreeMap<ModPath, Module>,
    /// The module whose code is being read.
    current: ModPath,
    /// Where the current module's child module files live.
    child_dir: PathBuf,
    file: PathBuf,
    /// Child modules declared with `mod name;`, to read from their own files.
    pending: Vec<(ModPath, PathBuf)>,
}

impl Reader<'_> {
    fn module(&mut self) -> &mut Module {
        self.modules.get_mut(&self.current).expect("the current module is registered")
    }

    /// Record each path of an import tree and the name it brings in.
    fn use_tree(&mut self, tree: &UseTree, prefix: &mut Vec<String>) {
        match tree {
            UseTree::Path(p) => {
                prefix.push(p.ident.unraw().to_string());
                self.use_tree(&p.tree, prefix);
                prefix.pop();
            }
            UseTree::Name(n) => self.imported(prefix, &n.ident.unraw().to_string(), None),
            UseTree::Rename(r) => self.imported(prefix, &r.ident.unraw().to_string(), Some(r.rename.to_string())),
            UseTree::Glob(_) => {
                let path = prefix.clone();
                self.module().paths.push(path);
            }
            UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(t, prefix);
                }
            }
        }
    }

    fn imported(&mut self, prefix: &[String], name: &str, rename: Option<String>) {
        let mut path = prefix.to_vec();
        if name != "self" {
            path.push(name.to_string());
        }
        let Some(last) = path.last().cloned() else { return };
        let module = self.module();
        module.aliases.insert(rename.unwrap_or(last), path.clone());
        module.paths.push(path);
    }

    /// A `mod` item: an inline module is read at once, a declared one queued with its file.
    fn module_item(&mut self, m: &syn::ItemMod) {
        let name = m.ident.unraw().to_string();
        self.module().children.insert(name.clone());
        let mut path = self.current.clone();
        path.push(name.clone());
        match &m.content {
            Some((_, items)) => {
                let outer = (self.current.clone(), self.child_dir.clone());
                self.modules.insert(path.clone(), Module { file: self.file.clone(), ..Module::default() });
                self.current = path;
                self.child_dir = self.child_dir.join(&name);
                for item in items {
                    self.visit_item(item);
                }
                (self.current, self.child_dir) = outer;
            }
            None => {
                let flat = self.child_dir.join(format!("{name}.rs"));
                let nested = self.child_dir.join(&name).join("mod.rs");
                let file = if flat.exists() { flat } else { nested };
                assert!(file.exists(), "{}: no file for `mod {name};`", self.file.display());
                self.pending.push((path, file));
            }
        }
    }
}

impl<'ast> Visit<'ast> for Reader<'_> {
    fn visit_item(&mut self, item: &'ast Item) {
        if test_only(item_attrs(item)) {
            return;
        }
        match item {
            Item::Mod(m) => self.module_item(m),
            Item::Use(u) if u.leading_colon.is_none() => self.use_tree(&u.tree, &mut Vec::new()),
            Item::Use(_) => {}
            _ => visit::visit_item(self, item),
        }
    }
    fn visit_impl_item(&mut self, item: &'ast ImplItem) {
        let attrs = match item {
            ImplItem::Const(i) => &i.attrs,
            ImplItem::Fn(i) => &i.attrs,
            ImplItem::Type(i) => &i.attrs,
            ImplItem::Macro(i) => &i.attrs,
            _ => &Vec::new(),
        };
        if !test_only(attrs) {
            visit::visit_impl_item(self, item);
        }
    }
    fn visit_trait_item(&mut self, item: &'ast TraitItem) {
        let attrs = match item {
            TraitItem::Const(i) => &i.attrs,
            TraitItem::Fn(i) => &i.attrs,
            TraitItem::Type(i) => &i.attrs,
            TraitItem::Macro(i) => &i.attrs,
            _ => &Vec::new(),
        };
        if !test_only(attrs) {
            visit::visit_trait_item(self, item);
        }
    }
    fn visit_stmt(&mut self, stmt: &'ast Stmt) {
        let attrs = match stmt {
            Stmt::Local(l) => &l.attrs[..],
            Stmt::Macro(m) => &m.attrs[..],
            Stmt::Item(_) | Stmt::Expr(..) => &[],
        };
        if !test_only(attrs) {
            visit::visit_stmt(self, stmt);
        }
    }
    fn visit_expr(&mut self, expr: &'ast Expr) {
        if !test_only(expr_attrs(expr)) {
            visit::visit_expr(self, expr);
        }
    }
    fn visit_field(&mut self, field: &'ast syn::Field) {
        if !test_only(&field.attrs) {
            visit::visit_field(self, field);
        }
    }
    fn visit_field_value(&mut self, field: &'ast syn::FieldValue) {
        if !test_only(&field.attrs) {
            visit::visit_field_value(self, field);
        }
    }
    fn visit_variant(&mut self, variant: &'ast syn::Variant) {
        if !test_only(&variant.attrs) {
            visit::visit_variant(self, variant);
        }
    }
    fn visit_arm(&mut self, arm: &'ast syn::Arm) {
        if !test_only(&arm.attrs) {
            visit::visit_arm(self, arm);
        }
    }
    fn visit_path(&mut self, path: &'ast syn::Path) {
        if path.leading_colon.is_none() && path.segments.len() > 1 {
            let segments = path.segments.iter().map(|s| s.ident.unraw().to_string()).collect();
            self.module().paths.push(segments);
        }
        visit::visit_path(self, path);
    }
    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        visit::visit_macro(self, mac);
        let mut found = Vec::new();
        token_paths(mac.tokens.clone(), &mut found);
        self.module().paths.extend(found);
    }
}

/// Every module a crate root (`lib.rs`, `main.rs`) builds without tests, along its `mod`
/// declarations.
fn read_crate(root: &Path) -> BTreeMap<ModPath, Module> {
    let mut modules = BTreeMap::new();
    let mut queue = vec![(ModPath::new(), root.to_path_buf())];
    while let Some((path, file)) = queue.pop() {
        let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let ast = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let dir = file.parent().expect("a file in a folder");
        let child_dir = if ["lib", "main", "mod"].contains(&stem) { dir.to_path_buf() } else { dir.join(stem) };
        modules.insert(path.clone(), Module { file: file.clone(), ..Module::default() });
        let mut reader = Reader { modules: &mut modules, current: path, child_dir, file, pending: Vec::new() };
        for item in &ast.items {
            reader.visit_item(item);
        }
        queue.extend(reader.pending);
    }
    modules
}

/// The module path a path written in `module` names, if it names one of the crate's: through
/// `crate::`, `super::`, `self::`, a child module, or a name imported into `module`.
fn resolve(modules: &BTreeMap<ModPath, Module>, module: &ModPath, written: &[String], depth: usize) -> Option<ModPath> {
    let (first, rest) = written.split_first()?;
    let mut base = match first.as_str() {
        "crate" => ModPath::new(),
        "self" | "super" => module.clone(),
        name if modules.get(module)?.children.contains(name) => {
            let mut base = module.clone();
            base.push(name.to_string());
            base
        }
        name => {
            let target = modules.get(module)?.aliases.get(name)?;
            if depth > 8 || target.first() == Some(first) && target.len() == 1 {
                return None;
            }
            let mut base = resolve(modules, module, target, depth + 1)?;
            base.extend(rest.iter().cloned());
            return Some(base);
        }
    };
    let mut rest = rest;
    if first == "super" {
        base.pop()?;
    }
    while let Some((next, tail)) = rest.split_first() {
        match next.as_str() {
            "super" => {
                base.pop()?;
            }
            "self" => {}
            _ => break,
        }
        rest = tail;
    }
    base.extend(rest.iter().cloned());
    Some(base)
}

/// Module-to-module arrows of one crate root, each to the longest module path it names, with
/// the first path written that makes it (for the failure message).
type Edges = BTreeMap<ModPath, BTreeMap<ModPath, String>>;

fn graph(root: &Path) -> Edges {
    arrows(&read_crate(root))
}

fn arrows(modules: &BTreeMap<ModPath, Module>) -> Edges {
    let mut edges = Edges::new();
    for (module, m) in modules {
        let targets = edges.entry(module.clone()).or_default();
        for written in &m.paths {
            let Some(named) = resolve(modules, module, written, 0) else { continue };
            let target = (0..=named.len()).rev().map(|k| named[..k].to_vec()).find(|p| modules.contains_key(p));
            if let Some(t) = target.filter(|t| t != module) {
                targets.entry(t).or_insert_with(|| format!("`{}` in {}", written.join("::"), m.file.display()));
            }
        }
    }
    edges
}

/// The core's modules and arrows, read once for the tests that look at them (parsing the
/// whole core takes seconds).
fn core() -> &'static (BTreeMap<ModPath, Module>, Edges) {
    static CORE: OnceLock<(BTreeMap<ModPath, Module>, Edges)> = OnceLock::new();
    CORE.get_or_init(|| {
        let modules = read_crate(&workspace().join("core/src/lib.rs"));
        let edges = arrows(&modules);
        (modules, edges)
    })
}

fn is_ancestor(a: &ModPath, b: &ModPath) -> bool {
    a.len() <= b.len() && b[..a.len()] == a[..] || b.len() <= a.len() && a[..b.len()] == b[..]
}

/// Arrows that close a circle: `a -> b` where `b` reaches `a` again, ancestors aside.
fn circles(edges: &Edges) -> Vec<String> {
    let next = |m: &ModPath| -> Vec<ModPath> {
        edges.get(m).map(|s| s.keys().filter(|n| !is_ancestor(m, n)).cloned().collect()).unwrap_or_default()
    };
    let reaches = |from: &ModPath, to: &ModPath| {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(m) = stack.pop() {
            if &m == to {
                return true;
            }
            if seen.insert(m.clone()) {
                stack.extend(next(&m));
            }
        }
        false
    };
    let mut out = Vec::new();
    for a in edges.keys() {
        for b in next(a) {
            if reaches(&b, a) {
                out.push(format!("{} -> {} ({})", a.join("::"), b.join("::"), edges[a][&b]));
            }
        }
    }
    out
}

/// The arrows between sibling subtrees: `a::x -> b::y` is the arrow `a -> b` between the
/// children of their common ancestor, a module standing for everything below it. A circle
/// here goes through submodules (`a -> b::inner -> a`) that module-to-module arrows, which
/// leave a module's own descendants aside, do not close.
fn between_siblings(edges: &Edges) -> Edges {
    let mut out = Edges::new();
    for (from, targets) in edges {
        for (to, witness) in targets.iter().filter(|(to, _)| !is_ancestor(from, to)) {
            let common = from.iter().zip(to).take_while(|(a, b)| a == b).count();
            let why = || format!("{} -> {}: {witness}", from.join("::"), to.join("::"));
            out.entry(from[..=common].to_vec()).or_default().entry(to[..=common].to_vec()).or_insert_with(why);
        }
    }
    out
}

/// Circles between modules and between sibling subtrees.
fn all_circles(edges: &Edges) -> Vec<String> {
    let mut found = circles(edges);
    found.extend(circles(&between_siblings(edges)).into_iter().map(|c| format!("between subtrees: {c}")));
    found
}

/// Arrows from a top-level module to one after it in `layers`.
fn upward_arrows(edges: &Edges, layers: &[&str]) -> Vec<String> {
    let rank = |m: &str| layers.iter().position(|l| *l == m);
    let mut wrong = Vec::new();
    for (from, targets) in edges {
        let Some(top) = from.first() else { continue };
        let from_rank = rank(top).unwrap_or_else(|| panic!("module `{top}` is missing from the layers"));
        for (to, witness) in targets {
            let Some(to_top) = to.first().filter(|t| *t != top) else { continue };
            let to_rank = rank(to_top).unwrap_or_else(|| panic!("module `{to_top}` is missing from the layers"));
            if to_rank > from_rank {
                wrong.push(format!("{} -> {} ({witness})", from.join("::"), to.join("::")));
            }
        }
    }
    wrong
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_path_buf()
}

#[test]
fn no_module_of_the_core_or_the_app_sits_in_an_import_circle() {
    let app = ["app/src/lib.rs", "app/src/main.rs"].map(|root| (root, graph(&workspace().join(root))));
    for (root, edges) in [("core/src/lib.rs", &core().1), (app[0].0, &app[0].1), (app[1].0, &app[1].1)] {
        let found = all_circles(edges);
        assert!(found.is_empty(), "{root}: arrows inside an import circle:\n{}", found.join("\n"));
    }
}

#[test]
fn every_arrow_between_core_stages_points_down_the_data_flow() {
    let wrong = upward_arrows(&core().1, CORE_LAYERS);
    assert!(wrong.is_empty(), "arrows from a lower stage to a higher one:\n{}", wrong.join("\n"));
}

#[test]
fn every_production_file_of_the_core_is_read_and_no_test_file() {
    let files: BTreeSet<&Path> = core().0.values().map(|m| m.file.as_path()).collect();
    for probe in ["bench/virtual_bench/mod.rs", "measure/track/kernel.rs", "measure/sweep/mod.rs", "session/writer.rs"]
    {
        assert!(files.contains(workspace().join("core/src").join(probe).as_path()), "{probe} is not read");
    }
    for test_file in ["measure/track/tests.rs", "measure/track/reference.rs", "session/tests.rs"] {
        assert!(!files.contains(workspace().join("core/src").join(test_file).as_path()), "{test_file} is read");
    }
}

/// A source tree in a temporary folder: `(path under src/, contents)`.
fn tree(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (path, text) in files {
        let path = dir.path().join("src").join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

const LAYERS: &[&str] = &["low", "mid", "high"];

/// A clean tree: arrows only downwards, test code that names higher layers (stripped), and
/// submodules that use each other one way.
fn clean_tree() -> Vec<(&'static str, &'static str)> {
    vec![
        ("lib.rs", "pub mod low;\npub mod mid;\npub mod high;\n"),
        ("low.rs", "pub struct L;\n#[cfg(test)]\nmod tests { use crate::high::H; }\n"),
        (
            "mid/mod.rs",
            "#[cfg(test)]\nmod tests;\nmod a;\nmod b;\nmod c;\nuse crate::{low::L, mid::a::A};\n\
             #[cfg(test)]\nuse crate::high::H;\n\
             pub fn f() { #[cfg(test)] { crate::high::g(); } let _ = (L, A); }\n",
        ),
        ("mid/tests.rs", "use crate::high::H;\n"),
        ("mid/a.rs", "pub struct A;\nuse super::b::B;\n"),
        ("mid/b.rs", "pub struct B;\nuse self::inner::I;\nmod inner { pub struct I; }\n"),
        ("mid/c.rs", "pub struct C;\n"),
        ("high.rs", "pub struct H;\npub fn g() { let _ = crate::mid::f(); format!(\"{:?}\", super::low::L); }\n"),
    ]
}

/// `files` with some files replaced.
fn with(mut files: Vec<(&'static str, &'static str)>, changed: &[(&'static str, &'static str)]) -> tempfile::TempDir {
    files.retain(|(p, _)| changed.iter().all(|(c, _)| c != p));
    files.extend_from_slice(changed);
    tree(&files)
}

fn check(dir: &tempfile::TempDir) -> (Vec<String>, Vec<String>) {
    let edges = graph(&dir.path().join("src/lib.rs"));
    (upward_arrows(&edges, LAYERS), all_circles(&edges))
}

#[test]
fn the_checker_passes_a_clean_tree_whose_tests_reach_anywhere() {
    let dir = tree(&clean_tree());
    assert_eq!(check(&dir), (vec![], vec![]));
    let edges = graph(&dir.path().join("src/lib.rs"));
    let m = |s: &str| s.split("::").map(String::from).collect::<ModPath>();
    assert!(edges[&m("mid")].contains_key(&m("low")) && edges[&m("mid")].contains_key(&m("mid::a")), "braced");
    assert!(edges[&m("mid::a")].contains_key(&m("mid::b")), "super::");
    assert!(edges[&m("high")].contains_key(&m("low")), "a path inside a macro's arguments");
}

#[test]
fn the_checker_sees_an_upward_arrow_after_an_early_test_module() {
    let mid = "#[cfg(test)]\nmod tests;\nmod a;\nmod b;\npub fn f() {}\nuse crate::high::H as _X;\n";
    let (up, _) = check(&with(clean_tree(), &[("mid/mod.rs", mid)]));
    assert_eq!(up.len(), 1, "{up:?}");
    assert!(up[0].starts_with("mid -> high"), "{up:?}");
    // The same after a test function and a test-only statement.
    let low = "#[cfg(test)]\nfn t() {}\npub fn l() { #[cfg(test)] let _x = 1; crate::mid::f(); }\n";
    let (up, _) = check(&with(clean_tree(), &[("low.rs", low)]));
    assert_eq!(up.len(), 1, "{up:?}");
    assert!(up[0].starts_with("low -> mid"), "{up:?}");
}

#[test]
fn the_checker_sees_an_upward_arrow_in_a_braced_import() {
    let low = "pub struct L;\nuse crate::{low::L as _L2, mid::{a::A, b}};\n";
    let (up, _) = check(&with(clean_tree(), &[("low.rs", low)]));
    assert!(
        up.iter().any(|a| a.starts_with("low -> mid::a")) && up.iter().any(|a| a.starts_with("low -> mid::b")),
        "{up:?}"
    );
    // Through a name an import brought in.
    let low = "pub struct L;\nuse crate::mid as m;\npub fn l() { m::f(); }\n";
    let (up, _) = check(&with(clean_tree(), &[("low.rs", low)]));
    assert!(!up.is_empty(), "{up:?}");
    // Through a raw identifier, which names the same module.
    let low = "pub struct L;\nuse crate::r#mid::a::A;\n";
    let (up, _) = check(&with(clean_tree(), &[("low.rs", low)]));
    assert!(up.iter().any(|a| a.starts_with("low -> mid::a")), "{up:?}");
}

#[test]
fn the_checker_sees_a_circle_through_submodules() {
    // mid::a -> mid::b (clean tree) -> mid::c -> mid::a, the last through a braced import.
    let b = "pub struct B;\nuse super::c::C;\n";
    let c = "pub struct C;\nuse crate::mid::{a::A, b};\n";
    let (up, circles) = check(&with(clean_tree(), &[("mid/b.rs", b), ("mid/c.rs", c)]));
    assert!(up.is_empty(), "{up:?}");
    for arrow in ["mid::a -> mid::b", "mid::b -> mid::c", "mid::c -> mid::a"] {
        assert!(circles.iter().any(|c| c.starts_with(arrow)), "no {arrow} in {circles:?}");
    }
    // mid::a -> mid::b, and mid::b's inner module back to mid::a: a circle between the two
    // subtrees that no two modules close alone.
    let b = "pub struct B;\nuse self::inner::I;\nmod inner { pub struct I; fn i() { crate::mid::a::f(); } }\n";
    let (up, circles) = check(&with(clean_tree(), &[("mid/b.rs", b)]));
    assert!(up.is_empty(), "{up:?}");
    let expected =
        ["between subtrees: mid::a -> mid::b", "between subtrees: mid::b -> mid::a (mid::b::inner -> mid::a"];
    for arrow in expected {
        assert!(circles.iter().any(|c| c.starts_with(arrow)), "no {arrow} in {circles:?}");
    }
    assert_eq!(circles.len(), 2, "{circles:?}");
}
