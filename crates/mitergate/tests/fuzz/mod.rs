//! Parser fuzzing: arbitrary text (characters that matter to the formats, any Unicode, lossy
//! bytes) and mutated valid documents (characters replaced, inserted or deleted, lines
//! duplicated or deleted) fed to the crate's text parsers: the gate TOML
//! ([`GateConfig::from_toml_str`]), `.inp` decks ([`InpModel::parse`], then the deck's mesh,
//! supports, loads and, for small decks, the factored model and a solve) and the import
//! sidecar ([`ImportSpec::from_toml_str`], then `validate`).
//!
//! The contract checked: `Ok` or `Err`, never a panic (a panic fails the property); on top of
//! that what the types document: a parsed gate configuration is valid and survives a TOML
//! round trip unchanged, a deck parse error names a line of the deck, and a validated import
//! frame is made of unit vectors. 256 cases per property on documents of at most a few
//! thousand characters (decks of 7 nodes): each property runs in about a second or less.
//!
//! `fuzz_seeds_are_valid_documents` checks that the documents the mutations start from are
//! valid, so that the mutated cases start from the happy path.

use mitergate::gate::DEFAULT_GATE_TOML;
use mitergate::inp::{ImportSpec, InpModel};
use mitergate::{GateConfig, GateError};
use proptest::prelude::*;
use proptest::sample::Index;

/// A small deck touching every keyword the reader supports: a heading, node and element
/// sets (continued lines, `GENERATE`, nested sets), S4R, S3 and B31 elements, a material with
/// a Fortran `D` exponent, shell and beam sections, `ENCASTRE`, a transformed roller, an
/// equation, and a step with loads and a skipped output request.
const DECK: &str = "\
** fuzz seed: two S4R, a triangle and a beam
*Heading
 fuzz seed deck
*Node, nset=All
1, 0., 0., 0.
2, 10., 0., 0.
3, 20., 0., 0.
4, 0., 10., 0.
5, 10., 10., 0.
6, 20., 10.
7, 20., 20., 0.
*Element, type=S4R,
 elset=Plate
1, 1, 2,
 5, 4
2, 2, 3, 6, 5
*Element, type=S3, elset=Tri
3, 5, 6, 7
*Element, type=B31, elset=Beam
4, 4, 5
*Nset, nset=Left
1, 4
*Nset, nset=Right, generate
3, 6, 3
*Elset, elset=Shells
Plate, Tri
*Material, name=Steel
*Elastic
29.0D6, 0.3
*Density
7.3e-4
*Shell Section, elset=Shells, material=steel
0.25
*Beam Section, elset=Beam, material=Steel, section=RECT
2.0, 4.0
0, 0, -1
*Boundary
Left, encastre
*Nset, nset=Roll
7
*Transform, nset=Roll
1, 0, 0, 0, 1, 0
*Boundary
Roll, 3
*Equation
2
6, 3, 1.0, 6, 1, -0.5
*Step
*Static
*Cload
Right, 3, 50.
7, 2, 1.5D1
*Node Print, nset=All
U
*End Step
";

/// An import sidecar with every key.
const SPEC: &str = "\
quoin_nset = \"QUOIN_LINE\"
skin_elset = \"SKIN\"
vertical = [0.0, 0.0, 1.0]
sill_elevation = 0.0
quoin_height = 762.0
quoin_normal = [1.0, 0.0, 0.0]
downstream = [0.0, 1.0, 0.0]
unit_weight = 0.0361
drilling_penalty = 1e-3
[[gauges]]
name = \"SG1\"
point = [96.0, 30.0, 18.0]
side = [0.0, 0.0, 1.0]
direction = [1.0, 0.0, 0.0]
elset = \"GAUGE_SG1\"
[[gauges]]
name = \"SG2\"
point = [96.0, 30.0, 52.6]
side = [0.0, 0.0, 1.0]
direction = [1.0, 0.0, 0.0]
";

/// Decks up to this size are also built (assembled, supported, factored) and solved: a
/// mutated seed deck stays far below it, so this only bounds the time of arbitrary ones.
const MAX_BUILT_NODES: usize = 64;

// ---------------------------------------------------------------------------------------------
// Strategies
// ---------------------------------------------------------------------------------------------

/// One edit of a document.
#[derive(Debug, Clone)]
enum Edit {
    Replace(Index, char),
    Insert(Index, char),
    Delete(Index),
    /// Copies a line to another position.
    DuplicateLine(Index, Index),
    DeleteLine(Index),
}

/// Characters that mean something to TOML, `.inp` decks or numbers, and now and then any
/// character.
fn format_char() -> impl Strategy<Value = char> {
    prop_oneof![
        4 => prop::sample::select(vec![
            ',', '"', '\'', '\n', '\r', '\t', ' ', '-', '+', '.', 'e', 'E', 'D', '0', '1', '9',
            '=', '[', ']', '{', '}', '#', '*', '\\', 'n', 'a', 'i', 'f', '\u{feff}', '\u{0}', 'µ',
        ]),
        1 => any::<char>(),
    ]
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<Index>(), format_char()).prop_map(|(i, c)| Edit::Replace(i, c)),
        (any::<Index>(), format_char()).prop_map(|(i, c)| Edit::Insert(i, c)),
        any::<Index>().prop_map(Edit::Delete),
        (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Edit::DuplicateLine(a, b)),
        any::<Index>().prop_map(Edit::DeleteLine),
    ]
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    prop::collection::vec(edit(), 1..8)
}

/// Arbitrary text: format characters, any Unicode, or bytes read lossily as UTF-8.
fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::collection::vec(format_char(), 0..300)
            .prop_map(|v| v.into_iter().collect::<String>()),
        any::<String>(),
        prop::collection::vec(any::<u8>(), 0..300)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
    ]
}

/// `text` after the edits.
fn mutate(text: &str, edits: &[Edit]) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for e in edits {
        match e {
            Edit::Replace(i, c) if !chars.is_empty() => {
                let k = i.index(chars.len());
                chars[k] = *c;
            }
            Edit::Insert(i, c) => {
                let k = i.index(chars.len() + 1);
                chars.insert(k, *c);
            }
            Edit::Delete(i) if !chars.is_empty() => {
                let k = i.index(chars.len());
                chars.remove(k);
            }
            Edit::DuplicateLine(a, b) => {
                let s: String = chars.iter().collect();
                let mut lines: Vec<&str> = s.split_inclusive('\n').collect();
                if !lines.is_empty() {
                    let line = lines[a.index(lines.len())];
                    lines.insert(b.index(lines.len() + 1), line);
                }
                chars = lines.concat().chars().collect();
            }
            Edit::DeleteLine(a) => {
                let s: String = chars.iter().collect();
                let mut lines: Vec<&str> = s.split_inclusive('\n').collect();
                if !lines.is_empty() {
                    lines.remove(a.index(lines.len()));
                }
                chars = lines.concat().chars().collect();
            }
            _ => {}
        }
    }
    chars.into_iter().collect()
}

// ---------------------------------------------------------------------------------------------
// Checks
// ---------------------------------------------------------------------------------------------

/// A parsed gate configuration is valid and its TOML reads back to the same configuration
/// (every number of a valid configuration is finite, so equality is exact).
fn check_gate(text: &str) -> Result<(), TestCaseError> {
    if let Ok(cfg) = GateConfig::from_toml_str(text) {
        prop_assert!(cfg.validate().is_ok());
        let back = cfg
            .to_toml_string()
            .map_err(|e| TestCaseError::fail(format!("a parsed gate does not serialise: {e}")))?;
        prop_assert_eq!(GateConfig::from_toml_str(&back).ok(), Some(cfg), "{}", back);
    }
    Ok(())
}

/// A deck: a parse error names a line of the text; a parsed deck's mesh, supports and loads
/// are `Ok` or `Err`, and a small one is built and solved.
fn check_deck(text: &str) -> Result<(), TestCaseError> {
    let deck = match InpModel::parse(text) {
        Ok(d) => d,
        Err(GateError::InpParse { line, reason }) => {
            let last = text.lines().count().max(1);
            prop_assert!(
                (1..=last).contains(&line),
                "parse error on line {line} of a {last}-line deck: {reason}"
            );
            return Ok(());
        }
        Err(_) => return Ok(()),
    };
    let _ = deck.to_shell_mesh();
    let _ = deck.supports(0);
    let _ = deck.step_load(0);
    if deck.nodes.len() <= MAX_BUILT_NODES
        && let Ok(model) = deck.build(1e-3)
        && let Ok(f) = model.step_load(0)
    {
        let _ = model.solve(&f);
    }
    Ok(())
}

/// An import sidecar: a validated frame is made of unit vectors.
fn check_spec(text: &str) -> Result<(), TestCaseError> {
    if let Ok(spec) = ImportSpec::from_toml_str(text)
        && let Ok(frame) = spec.validate()
    {
        for (name, v) in [
            ("vertical", frame.vertical),
            ("quoin_normal", frame.quoin_normal),
            ("quoin_tangent", frame.quoin_tangent),
            ("downstream", frame.downstream),
        ] {
            let norm = v.iter().map(|c| c * c).sum::<f64>().sqrt();
            // a normalised vector: round-off of three products and a square root
            prop_assert!((norm - 1.0).abs() < 1e-12, "{name} {v:?} of {spec:?}");
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn gate_toml_from_mutated_default_gate(e in edits()) {
        check_gate(&mutate(DEFAULT_GATE_TOML, &e))?;
    }

    #[test]
    fn gate_toml_from_any_text(t in text()) {
        check_gate(&t)?;
    }

    #[test]
    fn inp_decks_from_mutated_deck(e in edits()) {
        check_deck(&mutate(DECK, &e))?;
    }

    #[test]
    fn inp_decks_from_any_text(t in text()) {
        check_deck(&t)?;
    }

    #[test]
    fn import_specs_from_mutated_sidecar(e in edits()) {
        check_spec(&mutate(SPEC, &e))?;
    }

    #[test]
    fn import_specs_from_any_text(t in text()) {
        check_spec(&t)?;
    }
}

#[test]
fn fuzz_seeds_are_valid_documents() {
    GateConfig::from_toml_str(DEFAULT_GATE_TOML).unwrap();
    let deck = InpModel::parse(DECK).unwrap();
    assert_eq!((deck.nodes.len(), deck.elements.len()), (7, 4));
    assert_eq!(deck.nsets["RIGHT"], vec![3, 6]);
    assert_eq!(deck.elsets["SHELLS"], vec![1, 2, 3]);
    deck.to_shell_mesh().unwrap();
    deck.supports(0).unwrap();
    assert_eq!(deck.step_load(0).unwrap().len(), 6 * 7);
    // clamped along x = 0 (nodes 1 and 4): a stable model, so the mutations that keep it
    // stable exercise the build and the solve too
    let model = deck.build(1e-3).unwrap();
    let u = model.solve(&model.step_load(0).unwrap()).unwrap();
    assert!(u.iter().all(|v| v.is_finite()) && u.iter().any(|v| *v != 0.0));
    let spec = ImportSpec::from_toml_str(SPEC).unwrap();
    assert_eq!(spec.gauges.len(), 2);
    spec.validate().unwrap();
}
