//! docs/SCENE.md against the scene parser: every TOML example parses and
//! validates, and every key the parser accepts is documented.

use ltm_bake::{BakeError, SceneDesc};
use std::path::{Path, PathBuf};

fn scene_md() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/SCENE.md");
    std::fs::read_to_string(path).expect("docs/SCENE.md")
}

/// The ```toml blocks of `md`: the line (1-based) of each block's first
/// line, and its text.
fn toml_blocks(md: &str) -> Vec<(usize, String)> {
    let mut blocks = Vec::new();
    let mut open: Option<(usize, String)> = None;
    for (i, line) in md.lines().enumerate() {
        match open.as_mut() {
            None if line.trim_end() == "```toml" => open = Some((i + 2, String::new())),
            Some(_) if line.trim_end() == "```" => blocks.extend(open.take()),
            Some((_, text)) => {
                text.push_str(line);
                text.push('\n');
            }
            None => {}
        }
    }
    assert!(
        open.is_none(),
        "docs/SCENE.md: a ```toml block is not closed"
    );
    blocks
}

/// Every TOML example of docs/SCENE.md is a valid scene (mesh paths
/// relative to `assets/scenes/`, as the document says).
#[test]
fn every_toml_example_parses() {
    let blocks = toml_blocks(&scene_md());
    assert!(blocks.len() >= 6, "only {} TOML examples", blocks.len());
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/scenes");
    for (line, text) in blocks {
        let name = PathBuf::from(format!("docs/SCENE.md, the example at line {line}"));
        if let Err(e) = SceneDesc::parse(&text, &base, &name) {
            panic!("{e}");
        }
    }
}

/// A scene with every table: two materials of each type, a mesh, a quad
/// and a texture.
const FULL: &str = r#"
[camera]
eye = [0.0, 1.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 8

[lighting]
face_res = 2

[materials.matte]
type = "lambert"
albedo = [0.5, 0.5, 0.5]

[materials.shiny]
type = "glossy"
albedo = [0.5, 0.5, 0.5]
specular = [0.04, 0.04, 0.04]
roughness = 0.2

[[meshes]]
path = "m.obj"
material = "matte"

[[quads]]
center = [0.0, 0.0, 0.0]
size = [1.0, 1.0]
material = "shiny"

[texture]
mesh = 0
size = 8

[light_plane]
origin = [0.0, 1.0, 0.0]
x_axis = [1.0, 0.0, 0.0]
y_axis = [0.0, 0.0, 1.0]
"#;

/// The parser's message for `text`, which must be a syntax error.
fn syntax_error(text: &str) -> String {
    match SceneDesc::parse(text, Path::new("."), Path::new("probe.toml")) {
        Err(e @ BakeError::SceneSyntax { .. }) => e.to_string(),
        Err(e) => panic!("not a syntax error: {e}"),
        Ok(_) => panic!("accepted:\n{text}"),
    }
}

/// The names in backquotes after "expected" in a serde message.
fn expected_names(message: &str) -> Vec<String> {
    let (_, list) = message
        .split_once("expected")
        .unwrap_or_else(|| panic!("no list of expected names in: {message}"));
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The keys the parser accepts in the table whose header is `header` ("" for
/// the top level): it names them when it refuses an unknown key there.
fn accepted_keys(header: &str) -> Vec<String> {
    let probe = "undocumented_probe_key = 0\n";
    let text = if header.is_empty() {
        format!("{probe}{FULL}")
    } else {
        FULL.replacen(&format!("{header}\n"), &format!("{header}\n{probe}"), 1)
    };
    assert_ne!(text, FULL, "no table {header} in the probe scene");
    let message = syntax_error(&text);
    assert!(
        message.contains("unknown field `undocumented_probe_key`"),
        "{header}: {message}"
    );
    expected_names(&message)
}

/// The values of `texture.parameterization`, quoted, as the parser's
/// message for an unknown one lists them ("expected atlas, uv or sphere").
fn parameterizations() -> Vec<String> {
    let bad = FULL.replace(
        "size = 8\n",
        "size = 8\nparameterization = \"undocumented\"\n",
    );
    let message = syntax_error(&bad);
    let (_, list) = message.split_once("expected ").expect(&message);
    let list = list.split(')').next().unwrap_or(list);
    let names: Vec<String> = list
        .split(", ")
        .flat_map(|s| s.split(" or "))
        .map(|s| format!("\"{}\"", s.trim()))
        .collect();
    assert!(names.len() >= 3, "{message}");
    names
}

/// Every key the parser accepts, in every table, and every material type
/// is named in docs/SCENE.md (in backquotes), so that a key added to the
/// parser without its documentation fails here.
#[test]
fn every_key_is_documented() {
    let md = scene_md();
    let mut names = Vec::new();
    for header in [
        "",
        "[camera]",
        "[lighting]",
        "[materials.matte]",
        "[materials.shiny]",
        "[[meshes]]",
        "[[quads]]",
        "[texture]",
        "[light_plane]",
    ] {
        let keys = accepted_keys(header);
        assert!(!keys.is_empty(), "{header}: no keys");
        names.extend(keys.into_iter().map(|k| (header, k)));
    }
    let bad_type = FULL.replace("type = \"lambert\"", "type = \"undocumented\"");
    for t in expected_names(&syntax_error(&bad_type)) {
        names.push(("materials type", format!("\"{t}\"")));
    }
    names.push(("materials", "type".to_string()));
    names.extend(parameterizations().into_iter().map(|p| ("texture", p)));
    for (table, key) in names {
        // A top-level key is a table: `[camera]`, `[[meshes]]`, `[materials.NAME]`.
        let documented = match table {
            "" => md.contains(&format!("`[{key}")) || md.contains(&format!("`[[{key}")),
            _ => md.contains(&format!("`{key}`")),
        };
        assert!(
            documented,
            "docs/SCENE.md does not document `{key}` of {table}"
        );
    }
}
