//! Reading the document: child elements, `#id` references, numbers and colours, the
//! CMU462/CGL technique, and the element paths that errors and warnings name.

use super::Ctx;
use crate::io::LoadError;
use crate::math::Vec3;
use roxmltree::Node;

pub(super) fn children<'a, 'i>(n: Node<'a, 'i>, tag: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(move |c| c.is_element() && c.tag_name().name() == tag)
}

pub(super) fn child<'a, 'i>(n: Node<'a, 'i>, tag: &'static str) -> Option<Node<'a, 'i>> {
    children(n, tag).next()
}

pub(super) fn element_children<'a, 'i>(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(Node::is_element)
}

/// `<tag attr="…">` for messages.
pub(super) fn describe(n: Node) -> String {
    let tag = n.tag_name().name();
    for a in ["id", "url", "profile", "symbol", "semantic", "material", "target", "source"] {
        if let Some(v) = n.attribute(a) {
            return format!("<{tag} {a}=\"{v}\">");
        }
    }
    format!("<{tag}>")
}

/// The element's path from the nearest enclosing library object (geometry, node, effect…).
pub(super) fn elem_path(n: Node) -> String {
    const ANCHORS: [&str; 9] =
        ["geometry", "node", "effect", "material", "light", "camera", "visual_scene", "asset", "scene"];
    let mut parts = Vec::new();
    let mut cur = Some(n);
    while let Some(e) = cur.filter(Node::is_element) {
        parts.push(describe(e));
        if ANCHORS.contains(&e.tag_name().name()) {
            break;
        }
        cur = e.parent_element();
    }
    parts.reverse();
    parts.join("/")
}

/// The `<extra><technique profile="CMU462">` (or `"CGL"`) child of `n`, if any.
pub(super) fn cmu_technique<'a, 'i>(n: Node<'a, 'i>) -> Option<Node<'a, 'i>> {
    children(n, "extra")
        .flat_map(|e| children(e, "technique"))
        .find(|t| matches!(t.attribute("profile"), Some("CMU462") | Some("CGL")))
}

/// An error's location and message, for turning it into a warning.
pub(super) fn without_path(e: LoadError) -> String {
    match e {
        LoadError::Parse { location, message, .. } => format!("{location}: {message}"),
        other => other.to_string(),
    }
}

impl<'a, 'i> Ctx<'a, 'i> {
    pub(super) fn err(&self, n: Node, msg: impl Into<String>) -> LoadError {
        LoadError::parse(self.path, elem_path(n), msg)
    }

    pub(super) fn warn(&mut self, n: Node, msg: impl std::fmt::Display) {
        self.warnings.push(format!("{}: {msg}", elem_path(n)));
    }

    /// The element a `#id` attribute points to, which must have tag `want`.
    pub(super) fn resolve(&self, n: Node<'a, 'i>, attr: &str, want: &str) -> Result<Node<'a, 'i>, LoadError> {
        let url = n.attribute(attr).ok_or_else(|| self.err(n, format!("missing attribute {attr}")))?;
        let id = url.strip_prefix('#').ok_or_else(|| {
            self.err(n, format!("{attr}=\"{url}\": only references within the file (#id) are supported"))
        })?;
        let target =
            *self.ids.get(id).ok_or_else(|| self.err(n, format!("refers to a missing <{want} id=\"{id}\">")))?;
        if target.tag_name().name() != want {
            return Err(self.err(n, format!("{url} is a <{}>, not a <{want}>", target.tag_name().name())));
        }
        Ok(target)
    }

    pub(super) fn floats(&self, n: Node) -> Result<Vec<f32>, LoadError> {
        let text = n.text().unwrap_or("");
        let mut out = Vec::with_capacity(text.len() / 4);
        for (i, tok) in text.split_ascii_whitespace().enumerate() {
            let v: f32 = tok.parse().map_err(|_| self.err(n, format!("value {i} is {tok:?}, not a number")))?;
            out.push(v);
        }
        Ok(out)
    }

    pub(super) fn indices(&self, n: Node) -> Result<Vec<u32>, LoadError> {
        let text = n.text().unwrap_or("");
        let mut out = Vec::with_capacity(text.len() / 3);
        for (i, tok) in text.split_ascii_whitespace().enumerate() {
            let v: u32 = tok.parse().map_err(|_| self.err(n, format!("index {i} is {tok:?}, not a whole number")))?;
            out.push(v);
        }
        Ok(out)
    }

    pub(super) fn number(&self, n: Node) -> Result<f32, LoadError> {
        let v = self.floats(n)?;
        match v.as_slice() {
            [x, ..] if x.is_finite() => Ok(*x),
            [x, ..] => Err(self.err(n, format!("{x} is not a finite number"))),
            [] => Err(self.err(n, "expected a number, found nothing")),
        }
    }

    /// An RGB triple (a fourth alpha value is ignored), finite.
    pub(super) fn rgb(&self, n: Node) -> Result<Vec3, LoadError> {
        let v = self.floats(n)?;
        if v.len() < 3 {
            return Err(self.err(n, format!("expected 3 colour components, found {}", v.len())));
        }
        let c = Vec3::new(v[0], v[1], v[2]);
        if !c.is_finite() {
            return Err(self.err(n, "colour components must be finite"));
        }
        Ok(c)
    }

    pub(super) fn required(&self, n: Node<'a, 'i>, tag: &'static str) -> Result<Node<'a, 'i>, LoadError> {
        child(n, tag).ok_or_else(|| self.err(n, format!("missing <{tag}>")))
    }
}
