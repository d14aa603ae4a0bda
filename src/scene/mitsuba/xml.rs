//! The XML layer of the Mitsuba 3 loader: files parsed into one tree of [`Element`]s with
//! `<include>` spliced in and `$name` parameters replaced by their `<default>` values, and typed
//! access to an object's properties ([`Object`]) that remembers which ones were read, so that
//! every property gatetrace does not read is an error naming its file and line.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use anyhow::{Result, anyhow, bail};
use glam::{Mat3, Mat4, Vec3, Vec4};

/// How deep `<include>` may nest (a file including itself is caught by this bound).
const MAX_INCLUDE_DEPTH: usize = 16;

/// How deep elements may nest in one file (Mitsuba scenes nest a handful of levels; the bound
/// keeps the loader's recursion off the stack's end).
const MAX_NESTING: usize = 64;

/// An XML element with its parameters substituted, and where it was written.
#[derive(Clone, Debug)]
pub struct Element {
    /// The tag (`shape`, `bsdf`, `float`, ...).
    pub tag: String,
    /// Attributes in document order, `$name` parameters replaced.
    pub attributes: Vec<(String, String)>,
    /// Child elements in document order (comments and text dropped).
    pub children: Vec<Element>,
    /// The file the element was written in (as messages name it).
    pub file: Rc<str>,
    /// Its line in that file (1-based).
    pub line: u32,
}

impl Element {
    /// The attribute `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    /// `file:line: <tag type="..." name="...">` for messages.
    pub fn at(&self) -> String {
        let mut s = format!("{}:{}: <{}", self.file, self.line, self.tag);
        for key in ["type", "name", "id"] {
            if let Some(v) = self.attribute(key) {
                s += &format!(" {key}=\"{v}\"");
            }
        }
        s + ">"
    }

    /// An error at this element.
    pub fn error(&self, problem: impl std::fmt::Display) -> anyhow::Error {
        anyhow!("{}: {problem}", self.at())
    }

    /// The attribute `name`, or an error naming it.
    pub fn required(&self, name: &str) -> Result<&str> {
        self.attribute(name).ok_or_else(|| self.error(format!("the attribute `{name}` is missing")))
    }

    /// Errors on any attribute outside `allowed`.
    pub fn only_attributes(&self, allowed: &[&str]) -> Result<()> {
        match self.attributes.iter().find(|(k, _)| !allowed.contains(&k.as_str())) {
            Some((k, _)) => Err(self.error(format!("the attribute `{k}` is not understood here"))),
            None => Ok(()),
        }
    }
}

/// Reads `path` and every file it includes into the `<scene>` element, with its parameters
/// applied (`$name` in any attribute of any file replaced by the value `given` for it, else by
/// its `<default>`) and `<include>` elements replaced by the included file's children. Returns
/// the scene and a warning for each parameter given that no `$name` uses.
pub fn read_scene(path: &Path, given: &[(String, String)]) -> Result<(Element, Vec<String>)> {
    let mut scene = read_file(path, 0)?;
    if scene.tag != "scene" {
        bail!("{}: the root element is <{}>, not <scene>: not a Mitsuba scene", scene.at(), scene.tag);
    }
    let mut parameters: HashMap<String, String> = given.iter().cloned().collect();
    collect_defaults(&scene, &mut parameters)?;
    let mut used = std::collections::HashSet::new();
    substitute(&mut scene, &parameters, &mut used)?;
    let warnings = given
        .iter()
        .filter(|(name, _)| !used.contains(name))
        .map(|(name, _)| format!("{}: the parameter `{name}` is given, but the scene uses no ${name}", path.display()))
        .collect();
    Ok((scene, warnings))
}

/// One file's root element, its includes spliced in (`depth`: how many includes lead here).
fn read_file(path: &Path, depth: usize) -> Result<Element> {
    let name: Rc<str> = path.display().to_string().into();
    let text = std::fs::read_to_string(path).map_err(|e| anyhow!("{name}: cannot read the scene file: {e}"))?;
    let document = roxmltree::Document::parse(&text).map_err(|e| anyhow!("{name}: not well-formed XML: {e}"))?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    convert(&document, document.root_element(), &name, &base, depth, 0)
}

/// The element of `node` (at nesting `level` in its file) with its children, includes spliced.
fn convert(
    document: &roxmltree::Document,
    node: roxmltree::Node,
    file: &Rc<str>,
    base: &Path,
    depth: usize,
    level: usize,
) -> Result<Element> {
    let line = document.text_pos_at(node.range().start).row;
    if level > MAX_NESTING {
        bail!("{file}:{line}: elements nest deeper than {MAX_NESTING} levels");
    }
    let mut element = Element {
        tag: node.tag_name().name().to_owned(),
        attributes: node.attributes().map(|a| (a.name().to_owned(), a.value().to_owned())).collect(),
        children: Vec::new(),
        file: file.clone(),
        line,
    };
    for child in node.children().filter(roxmltree::Node::is_element) {
        let child = convert(document, child, file, base, depth, level + 1)?;
        if child.tag != "include" {
            element.children.push(child);
            continue;
        }
        child.only_attributes(&["filename"])?;
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(child.error(format!("includes nest deeper than {MAX_INCLUDE_DEPTH} files (a cycle?)")));
        }
        let included: PathBuf = base.join(child.required("filename")?);
        let root = read_file(&included, depth + 1).map_err(|e| child.error(format!("{e:#}")))?;
        if root.tag != "scene" {
            return Err(child.error(format!("the included file's root is <{}>, not <scene>", root.tag)));
        }
        element.children.extend(root.children);
    }
    Ok(element)
}

/// The `<default name value>` elements directly under the scene, first one of a name wins.
fn collect_defaults(scene: &Element, parameters: &mut HashMap<String, String>) -> Result<()> {
    for d in scene.children.iter().filter(|c| c.tag == "default") {
        d.only_attributes(&["name", "value"])?;
        let name = d.required("name")?;
        let value = d.required("value")?;
        parameters.entry(name.to_owned()).or_insert_with(|| value.to_owned());
    }
    Ok(())
}

/// Replaces `$name` in every attribute below `element` (a `$` not followed by a name is kept),
/// recording the names in `used`.
fn substitute(
    element: &mut Element,
    parameters: &HashMap<String, String>,
    used: &mut std::collections::HashSet<String>,
) -> Result<()> {
    let at = element.at();
    for (_, value) in element.attributes.iter_mut() {
        if !value.contains('$') {
            continue;
        }
        let mut out = String::new();
        let mut rest = value.as_str();
        while let Some(i) = rest.find('$') {
            out += &rest[..i];
            let tail = &rest[i + 1..];
            let len = tail.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(tail.len());
            if len == 0 {
                out.push('$');
            } else {
                let name = &tail[..len];
                match parameters.get(name) {
                    Some(v) => {
                        out += v;
                        used.insert(name.to_owned());
                    }
                    None => bail!("{at}: the parameter ${name} has no <default name=\"{name}\" value=\"...\"/>"),
                }
            }
            rest = &tail[len..];
        }
        out += rest;
        *value = out;
    }
    for child in &mut element.children {
        substitute(child, parameters, used)?;
    }
    Ok(())
}

/// Parses a list of numbers separated by commas and/or whitespace.
pub fn numbers(text: &str) -> Option<Vec<f32>> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f32>().ok().filter(|x| x.is_finite()))
        .collect()
}

/// A scene object (`<shape>`, `<bsdf>`, `<emitter>`, ...) whose properties are read by name.
/// Every property read is marked, and [`Object::finish`] refuses the ones left unread.
pub struct Object<'e> {
    /// The object's element.
    pub element: &'e Element,
    read: RefCell<Vec<bool>>,
}

/// The property tags (children named by a `name` attribute holding a value).
const PROPERTY_TAGS: [&str; 9] =
    ["integer", "float", "boolean", "string", "rgb", "spectrum", "point", "vector", "transform"];

impl<'e> Object<'e> {
    pub fn new(element: &'e Element) -> Self {
        Self { element, read: RefCell::new(vec![false; element.children.len()]) }
    }

    /// The object's `type` attribute.
    pub fn kind(&self) -> Result<&'e str> {
        self.element.required("type")
    }

    /// The child property named `name` (any property tag), marked as read.
    fn property(&self, name: &str) -> Option<&'e Element> {
        let i = self
            .element
            .children
            .iter()
            .position(|c| PROPERTY_TAGS.contains(&c.tag.as_str()) && c.attribute("name") == Some(name))?;
        self.read.borrow_mut()[i] = true;
        Some(&self.element.children[i])
    }

    /// Marks properties gatetrace knowingly ignores (they change nothing it renders).
    pub fn ignore(&self, names: &[&str]) {
        for name in names {
            let _ = self.property(name);
        }
    }

    /// The property's `value` attribute, checking its tag is one of `tags`.
    fn value(&self, name: &str, tags: &[&str]) -> Result<Option<(&'e Element, &'e str)>> {
        let Some(p) = self.property(name) else { return Ok(None) };
        if !tags.contains(&p.tag.as_str()) {
            return Err(p.error(format!("`{name}` must be given as <{}>", tags.join("> or <"))));
        }
        Ok(Some((p, p.required("value")?)))
    }

    /// A `<float>` (or `<integer>`) property.
    pub fn float(&self, name: &str) -> Result<Option<f32>> {
        let Some((p, v)) = self.value(name, &["float", "integer"])? else { return Ok(None) };
        match v.trim().parse::<f32>() {
            Ok(x) if x.is_finite() => Ok(Some(x)),
            _ => Err(p.error(format!("`{v}` is not a finite number"))),
        }
    }

    /// An `<integer>` property.
    pub fn integer(&self, name: &str) -> Result<Option<i64>> {
        let Some((p, v)) = self.value(name, &["integer"])? else { return Ok(None) };
        v.trim().parse::<i64>().map(Some).map_err(|_| p.error(format!("`{v}` is not an integer")))
    }

    /// A `<boolean>` property (`true` or `false`, any case).
    pub fn boolean(&self, name: &str) -> Result<Option<bool>> {
        let Some((p, v)) = self.value(name, &["boolean"])? else { return Ok(None) };
        match v.trim().to_ascii_lowercase().as_str() {
            "true" => Ok(Some(true)),
            "false" => Ok(Some(false)),
            _ => Err(p.error(format!("`{v}` is not true or false"))),
        }
    }

    /// A `<float>` or `<string>` property (a number or the name of one, such as an index of
    /// refraction): Ok(Some(Ok(number))) or Ok(Some(Err(name))).
    pub fn float_or_name(&self, name: &str) -> Result<Option<std::result::Result<f32, &'e str>>> {
        let Some((p, v)) = self.value(name, &["float", "integer", "string"])? else { return Ok(None) };
        if p.tag == "string" {
            return Ok(Some(Err(v)));
        }
        match v.trim().parse::<f32>() {
            Ok(x) if x.is_finite() => Ok(Some(Ok(x))),
            _ => Err(p.error(format!("`{v}` is not a finite number"))),
        }
    }

    /// A `<string>` property.
    pub fn string(&self, name: &str) -> Result<Option<&'e str>> {
        Ok(self.value(name, &["string"])?.map(|(_, v)| v))
    }

    /// A colour: `<rgb>` (three values, or one for grey), `<float>`, or a `<spectrum>` holding a
    /// single value (a constant spectrum); spectra sampled at wavelengths are refused.
    pub fn color(&self, name: &str) -> Result<Option<Vec3>> {
        let Some(p) = self.property(name) else { return Ok(None) };
        let v = p.required("value")?;
        if p.tag == "spectrum" && v.contains(':') {
            return Err(p.error(
                "spectra sampled at wavelengths are not read (gatetrace renders RGB): give an <rgb> value or a \
                 single constant",
            ));
        }
        let parsed = numbers(v).ok_or_else(|| p.error(format!("`{v}` is not a list of finite numbers")))?;
        match (p.tag.as_str(), parsed.as_slice()) {
            ("rgb", [r, g, b]) => Ok(Some(Vec3::new(*r, *g, *b))),
            ("rgb" | "float" | "spectrum", [x]) => Ok(Some(Vec3::splat(*x))),
            ("rgb", _) => Err(p.error(format!("`{v}`: an <rgb> value needs 3 numbers (or 1 for grey)"))),
            (tag, _) => Err(p.error(format!("`{name}` must be an <rgb>, <spectrum> or <float>, not <{tag}>"))),
        }
    }

    /// A `<point>` or `<vector>` property: `value="x, y, z"` or x, y, z attributes (each 0 when
    /// absent).
    pub fn point(&self, name: &str) -> Result<Option<Vec3>> {
        let Some(p) = self.property(name) else { return Ok(None) };
        if !matches!(p.tag.as_str(), "point" | "vector") {
            return Err(p.error(format!("`{name}` must be a <point> or <vector>")));
        }
        triple(p, 0.0).map(Some)
    }

    /// A `<transform>` property as a matrix (identity when absent).
    pub fn transform(&self, name: &str) -> Result<Mat4> {
        match self.property(name) {
            None => Ok(Mat4::IDENTITY),
            Some(p) if p.tag == "transform" => parse_transform(p),
            Some(p) => Err(p.error(format!("`{name}` must be a <transform>"))),
        }
    }

    /// Errors on the first child that was not read and is not among the object tags in
    /// `objects` (nested objects the caller reads itself: `bsdf`, `emitter`, `ref`, ...).
    pub fn finish(&self, objects: &[&str]) -> Result<()> {
        let read = self.read.borrow();
        for (child, read) in self.element.children.iter().zip(read.iter()) {
            if *read || objects.contains(&child.tag.as_str()) {
                continue;
            }
            let owner = format!("<{} type=\"{}\">", self.element.tag, self.element.attribute("type").unwrap_or("?"));
            return Err(if PROPERTY_TAGS.contains(&child.tag.as_str()) {
                child.error(format!("the property is not read by gatetrace's {owner} (it would change the image)"))
            } else {
                child.error(format!("a <{}> is not understood inside {owner}", child.tag))
            });
        }
        Ok(())
    }
}

/// A triple from `value="a, b, c"` (one number: all three) or `x`, `y`, `z` attributes (each
/// `fill` when absent).
fn triple(e: &Element, fill: f32) -> Result<Vec3> {
    if let Some(v) = e.attribute("value") {
        let n = numbers(v).ok_or_else(|| e.error(format!("`{v}` is not a list of finite numbers")))?;
        return match n.as_slice() {
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            [x] => Ok(Vec3::splat(*x)),
            _ => Err(e.error(format!("`{v}`: 3 numbers are needed"))),
        };
    }
    let axis = |key: &str| -> Result<f32> {
        match e.attribute(key) {
            None => Ok(fill),
            Some(v) => v
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| e.error(format!("{key}=\"{v}\" is not a finite number"))),
        }
    };
    Ok(Vec3::new(axis("x")?, axis("y")?, axis("z")?))
}

/// A `<transform>`: its operations applied in order (each one after those before it).
pub fn parse_transform(t: &Element) -> Result<Mat4> {
    let mut m = Mat4::IDENTITY;
    for op in &t.children {
        let step = match op.tag.as_str() {
            "translate" => {
                op.only_attributes(&["x", "y", "z", "value"])?;
                Mat4::from_translation(triple(op, 0.0)?)
            }
            "scale" => {
                op.only_attributes(&["x", "y", "z", "value"])?;
                Mat4::from_scale(triple(op, 1.0)?)
            }
            "rotate" => {
                op.only_attributes(&["x", "y", "z", "value", "angle"])?;
                let axis = triple(op, 0.0)?;
                let angle = op.required("angle")?;
                let degrees = angle
                    .trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|a| a.is_finite())
                    .ok_or_else(|| op.error(format!("angle=\"{angle}\" is not a finite number of degrees")))?;
                let axis = axis.try_normalize().ok_or_else(|| op.error("the rotation axis is zero"))?;
                Mat4::from_axis_angle(axis, degrees.to_radians())
            }
            "matrix" => {
                op.only_attributes(&["value"])?;
                let v = op.required("value")?;
                let n = numbers(v).ok_or_else(|| op.error(format!("`{v}` is not a list of finite numbers")))?;
                match n.len() {
                    // Row-major, as written.
                    16 => Mat4::from_cols_array(&n.try_into().expect("16 values")).transpose(),
                    9 => Mat4::from_mat3(Mat3::from_cols_array(&n.try_into().expect("9 values")).transpose()),
                    k => return Err(op.error(format!("a matrix needs 16 (or 9) numbers, not {k}"))),
                }
            }
            "lookat" => {
                op.only_attributes(&["origin", "target", "up"])?;
                let vector = |key: &str| -> Result<Option<Vec3>> {
                    op.attribute(key)
                        .map(|v| match numbers(v).as_deref() {
                            Some([x, y, z]) => Ok(Vec3::new(*x, *y, *z)),
                            _ => Err(op.error(format!("{key}=\"{v}\" is not three numbers"))),
                        })
                        .transpose()
                };
                let origin = vector("origin")?.ok_or_else(|| op.error("`origin` is missing"))?;
                let target = vector("target")?.ok_or_else(|| op.error("`target` is missing"))?;
                let dir = (target - origin).try_normalize().ok_or_else(|| op.error("origin and target coincide"))?;
                let up = vector("up")?.unwrap_or_else(|| dir.any_orthonormal_vector());
                let left = up.cross(dir).try_normalize().ok_or_else(|| op.error("`up` is parallel to the view"))?;
                let new_up = dir.cross(left);
                Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0))
            }
            other => return Err(op.error(format!("<{other}> is not a transform operation"))),
        };
        m = step * m;
    }
    if !m.is_finite() || m.row(3) != Vec4::W {
        return Err(t.error("the transform is not a finite affine map"));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn element(xml: &str) -> Element {
        let doc = roxmltree::Document::parse(xml).unwrap();
        convert(&doc, doc.root_element(), &Rc::from("t.xml"), Path::new("."), 0, 0).unwrap()
    }

    #[test]
    fn transforms_apply_in_order_and_lookat_faces_its_target() {
        let t = element(
            "<transform name=\"to_world\"><scale value=\"2\"/><rotate z=\"1\" angle=\"90\"/>\
             <translate x=\"1\"/></transform>",
        );
        let m = parse_transform(&t).unwrap();
        // (1, 0, 0) -> scaled (2, 0, 0) -> rotated (0, 2, 0) -> translated (1, 2, 0).
        assert!(m.transform_point3(Vec3::X).abs_diff_eq(Vec3::new(1.0, 2.0, 0.0), 1e-5));
        let t = element("<transform><matrix value=\"1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1\"/></transform>");
        assert!(parse_transform(&t).unwrap().transform_point3(Vec3::ZERO).abs_diff_eq(Vec3::new(5.0, 6.0, 7.0), 0.0));
        let t = element("<transform><lookat origin=\"0, 0, 2\" target=\"0, 0, 0\" up=\"0, 1, 0\"/></transform>");
        let m = parse_transform(&t).unwrap();
        assert!(m.z_axis.truncate().abs_diff_eq(Vec3::NEG_Z, 1e-6), "looks along local +z");
        assert!(m.x_axis.truncate().abs_diff_eq(Vec3::NEG_X, 1e-6), "local +x is the image's left");
        assert!(m.w_axis.truncate().abs_diff_eq(Vec3::new(0.0, 0.0, 2.0), 0.0));
        let bad = element("<transform><shear value=\"1\"/></transform>");
        assert!(parse_transform(&bad).unwrap_err().to_string().contains("t.xml:1: <shear"));
    }

    #[test]
    fn parameters_are_substituted_and_unknown_ones_named() {
        let mut e = element("<scene><default name=\"spp\" value=\"16\"/><integer name=\"n\" value=\"$spp\"/></scene>");
        let mut p = HashMap::new();
        collect_defaults(&e, &mut p).unwrap();
        substitute(&mut e, &p, &mut Default::default()).unwrap();
        assert_eq!(e.children[1].attribute("value"), Some("16"));
        // A value given replaces the default.
        let mut e = element("<scene><default name=\"spp\" value=\"16\"/><integer name=\"n\" value=\"$spp\"/></scene>");
        let mut p = HashMap::from([("spp".to_owned(), "4".to_owned())]);
        collect_defaults(&e, &mut p).unwrap();
        substitute(&mut e, &p, &mut Default::default()).unwrap();
        assert_eq!(e.children[1].attribute("value"), Some("4"));
        let mut e = element("<scene>\n<float name=\"x\" value=\"$nope\"/></scene>");
        let err = substitute(&mut e, &HashMap::new(), &mut Default::default()).unwrap_err().to_string();
        assert!(err.contains("t.xml:2") && err.contains("$nope"), "{err}");
    }

    #[test]
    fn unread_properties_are_refused_with_their_line() {
        let e = element(
            "<bsdf type=\"diffuse\">\n<rgb name=\"reflectance\" value=\"0.1, 0.2, 0.3\"/>\n<float name=\"sheen\" value=\"1\"/></bsdf>",
        );
        let o = Object::new(&e);
        assert_eq!(o.color("reflectance").unwrap(), Some(Vec3::new(0.1, 0.2, 0.3)));
        let err = o.finish(&[]).unwrap_err().to_string();
        assert!(err.contains("t.xml:3") && err.contains("sheen"), "{err}");
    }
}
