//! Scene files that are not glTF 2.0: recognised by their content (XML, OBJ, PLY, STL, FBX,
//! Blender and USD signatures) or, when the content says nothing, by their extension, so that
//! a Mitsuba 3 XML scene goes to its own loader and for any other file the error says what it is
//! and how to turn it into a scene gatetrace reads.

use std::path::Path;

/// What every message about a foreign scene file says about the formats gatetrace reads.
const SUPPORTED: &str = "gatetrace reads glTF 2.0 scenes (.gltf or .glb) and Mitsuba 3 XML scenes";

/// How to render a bare mesh: reference it from a Mitsuba scene beside a sensor and an emitter.
const MESH_IN_XML: &str = "or reference it from a Mitsuba 3 XML scene (<shape type=\"obj\"> or <shape type=\"ply\"> \
                           beside a <sensor> and an <emitter>; docs/scenes.md)";

/// How to get a glTF 2.0 file out of Blender, where most formats can be imported.
const BLENDER_EXPORT: &str =
    "export glTF 2.0 (File > Export > glTF 2.0 (.glb/.gltf), with Include > Cameras and Punctual Lights ticked)";

/// A scene format gatetrace does not read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Foreign {
    Obj,
    Ply,
    Stl,
    Fbx,
    Collada,
    Usd,
    Blend,
    Alembic,
    MitsubaXml,
    /// XML that is neither Mitsuba nor COLLADA.
    Xml,
}

impl Foreign {
    /// The format's name in messages.
    fn describe(self) -> &'static str {
        match self {
            Foreign::Obj => "a Wavefront OBJ mesh",
            Foreign::Ply => "a PLY mesh",
            Foreign::Stl => "an STL mesh",
            Foreign::Fbx => "an Autodesk FBX scene",
            Foreign::Collada => "a COLLADA scene",
            Foreign::Usd => "a Universal Scene Description (USD) scene",
            Foreign::Blend => "a Blender file",
            Foreign::Alembic => "an Alembic file",
            Foreign::MitsubaXml => "a Mitsuba XML scene",
            Foreign::Xml => "an XML file",
        }
    }

    /// What to do with a file of this format.
    fn advice(self) -> String {
        let import = |menu: &str, missing: &str| {
            format!(
                "import it into Blender (File > Import > {menu}){missing} and {BLENDER_EXPORT}; gatetrace needs a \
                 camera and an emissive material or a KHR_lights_punctual light"
            )
        };
        match self {
            Foreign::Obj => {
                import("Wavefront (.obj)", ", add a camera and a light (OBJ has neither)") + "; " + MESH_IN_XML
            }
            Foreign::Ply => {
                import("Stanford PLY (.ply)", ", add a camera, materials and a light (PLY has none)")
                    + "; "
                    + MESH_IN_XML
            }
            Foreign::Stl => import("STL (.stl)", ", add a camera, materials and a light (STL has none)"),
            Foreign::Fbx => import("FBX (.fbx)", ""),
            Foreign::Collada => import("Collada (.dae), in Blender 4.x", ""),
            Foreign::Usd => import("Universal Scene Description", ""),
            Foreign::Alembic => import("Alembic (.abc)", ", add materials"),
            Foreign::Blend => format!(
                "open it in Blender and {BLENDER_EXPORT}; gatetrace needs a camera and an emissive material or a \
                 KHR_lights_punctual light"
            ),
            Foreign::MitsubaXml => {
                "load it as a scene (gatetrace render and the Python package read Mitsuba XML; in the library, \
                 gatetrace::scene::load_scene_with)"
                    .into()
            }
            Foreign::Xml => format!(
                "XML files other than Mitsuba 3 scenes (a <scene> root) are not read: {BLENDER_EXPORT} from Blender \
                 instead"
            ),
        }
    }

    /// The format a file extension (any case, without the dot) names, if any.
    fn from_extension(extension: &str) -> Option<Foreign> {
        Some(match extension.to_ascii_lowercase().as_str() {
            "obj" => Foreign::Obj,
            "ply" => Foreign::Ply,
            "stl" => Foreign::Stl,
            "fbx" => Foreign::Fbx,
            "dae" => Foreign::Collada,
            "usd" | "usda" | "usdc" | "usdz" => Foreign::Usd,
            "blend" => Foreign::Blend,
            "abc" => Foreign::Alembic,
            "xml" => Foreign::Xml,
            _ => return None,
        })
    }

    /// The format the bytes of a file show, if any (None for what may be glTF: JSON, GLB, an
    /// empty file, or content without a signature gatetrace knows).
    fn from_content(bytes: &[u8]) -> Option<Foreign> {
        let text = trimmed(bytes);
        if text.is_empty() || may_be_gltf(bytes) {
            return None;
        }
        // The first 4 KiB are enough for every signature below.
        let head = String::from_utf8_lossy(&text[..text.len().min(4096)]);
        if text.starts_with(b"Kaydara FBX Binary") || head.starts_with("; FBX") {
            return Some(Foreign::Fbx);
        }
        if bytes.starts_with(b"BLENDER") {
            return Some(Foreign::Blend);
        }
        if head.starts_with("#usda") || bytes.starts_with(b"PXR-USDC") {
            return Some(Foreign::Usd);
        }
        if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
            return Some(Foreign::Ply);
        }
        if bytes.starts_with(b"Ogawa") {
            return Some(Foreign::Alembic);
        }
        if text.starts_with(b"<") {
            return Some(if head.contains("<COLLADA") {
                Foreign::Collada
            } else if head.contains("<scene") {
                Foreign::MitsubaXml
            } else {
                Foreign::Xml
            });
        }
        if head.starts_with("solid ") && head.contains("facet") {
            return Some(Foreign::Stl);
        }
        // Binary STL: an 80-byte header, a triangle count, and 50 bytes per triangle.
        if bytes.len() >= 84 {
            let count = u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as u64;
            if 84 + 50 * count == bytes.len() as u64 {
                return Some(Foreign::Stl);
            }
        }
        // OBJ: comments, then statements such as `v 1 2 3`, `o name`, `mtllib file.mtl`.
        const OBJ_STATEMENTS: [&str; 11] = ["v", "vn", "vt", "vp", "f", "l", "o", "g", "s", "mtllib", "usemtl"];
        let first_statement = head.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'));
        match first_statement {
            Some(line) if OBJ_STATEMENTS.contains(&line.split_whitespace().next().unwrap_or("")) => Some(Foreign::Obj),
            None if head.starts_with('#') => Some(Foreign::Obj),
            _ => None,
        }
    }
}

/// True when the file at `path` reads as a Mitsuba XML scene (XML whose first 4 KiB hold a
/// `<scene` element); false for anything else, or a file that cannot be read (whose loader then
/// says why).
pub fn is_mitsuba_xml(path: &Path) -> bool {
    use std::io::Read as _;
    let mut head = Vec::new();
    let read = std::fs::File::open(path).and_then(|f| f.take(4096).read_to_end(&mut head));
    read.is_ok() && Foreign::from_content(&head) == Some(Foreign::MitsubaXml)
}

/// The error for a scene file whose content or extension shows a format other than glTF 2.0
/// (`name`: the file as messages name it), or None when it may be glTF (whose own parser then
/// reports what is wrong). The content decides: a glTF file under another extension loads, and a
/// misnamed foreign file is named for what it is.
pub fn foreign_format_error(name: &str, path: &Path, bytes: &[u8]) -> Option<String> {
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let (format, by) = match Foreign::from_content(bytes) {
        Some(format) => (format, "by its content"),
        None if may_be_gltf(bytes) => return None,
        None => (Foreign::from_extension(extension)?, "by its extension"),
    };
    Some(format!(
        "{name}: {} ({by}), not a glTF 2.0 file: {SUPPORTED}. {}",
        format.describe(),
        capitalise(&format.advice())
    ))
}

/// The advice for the end of a message on a file that is not valid glTF under an extension other
/// than .gltf or .glb ("" for those two).
pub fn supported_formats_hint(path: &Path) -> String {
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if extension == "gltf" || extension == "glb" { String::new() } else { format!("; {SUPPORTED}") }
}

/// The bytes without a UTF-8 byte order mark and leading whitespace.
fn trimmed(bytes: &[u8]) -> &[u8] {
    let text = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    let start = text.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(text.len());
    &text[start..]
}

/// True for a GLB container or a JSON object: what glTF's own parser must judge.
fn may_be_gltf(bytes: &[u8]) -> bool {
    bytes.starts_with(b"glTF") || trimmed(bytes).starts_with(b"{")
}

fn capitalise(s: &str) -> String {
    let mut chars = s.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_outranks_extension() {
        let path = Path::new("scene.gltf");
        let xml = b"<?xml version=\"1.0\"?>\n<scene version=\"3.0.0\">\n</scene>\n";
        let e = foreign_format_error("scene.gltf", path, xml).unwrap();
        assert!(e.contains("Mitsuba XML") && e.contains("by its content"), "{e}");
        let obj = b"# Blender export\nmtllib plane.mtl\no Plane\nv 0 0 0\n";
        assert!(foreign_format_error("scene.gltf", path, obj).unwrap().contains("Wavefront OBJ"));
        assert!(foreign_format_error("x", Path::new("x.obj"), b"ply\nformat ascii 1.0\n").unwrap().contains("PLY"));
        assert!(foreign_format_error("x.obj", Path::new("x.obj"), b"  {\"asset\": {}}").is_none(), "JSON may be glTF");
        assert!(foreign_format_error("x.gltf", path, b"").is_none(), "empty: the glTF parser reports it");
        assert!(foreign_format_error("x.gltf", path, b"glTF\x02\0\0\0").is_none());
        let e = foreign_format_error("x.fbx", Path::new("x.fbx"), b"\0\x01garbage").unwrap();
        assert!(e.contains("FBX") && e.contains("by its extension"), "{e}");
        assert!(foreign_format_error("x.txt", Path::new("x.txt"), b"hello").is_none());
    }

    #[test]
    fn binary_stl_is_recognised_by_its_length() {
        let mut stl = vec![0u8; 84 + 2 * 50];
        stl[80..84].copy_from_slice(&2u32.to_le_bytes());
        assert!(foreign_format_error("m.gltf", Path::new("m.gltf"), &stl).unwrap().contains("STL"));
    }
}
