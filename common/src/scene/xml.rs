//! Reads the XML into a small tree with line numbers and `$name` parameters substituted.

use std::collections::HashMap;
use std::path::Path;

use super::SceneError;

/// Deepest element nesting accepted. Mitsuba scenes nest a handful of levels; the limit keeps
/// the recursive conversion below (and the builders after it) far from the stack's end.
pub(crate) const MAX_DEPTH: usize = 100;

/// Most bytes `$name` substitution may produce over a whole scene. Parameters may refer to
/// parameters, so a 1 KB file could otherwise ask for gigabytes (an expansion bomb).
pub(crate) const MAX_EXPANSION: usize = 16 << 20;

/// One XML element, with what errors need to point at it.
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub tag: String,
    pub attrs: Vec<(String, String)>,
    pub line: u32,
    pub children: Vec<Element>,
}

impl Element {
    pub fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The element as a user would recognise it: its tag with `type`, `name` and `id`.
    pub fn describe(&self) -> String {
        let mut s = format!("<{}", self.tag);
        for key in ["type", "name", "id"] {
            if let Some(v) = self.attr(key) {
                s.push_str(&format!(" {key}=\"{v}\""));
            }
        }
        s.push('>');
        s
    }
}

/// Parses `text` (the contents of `file`); `defines` are the command line's `-D name=value`,
/// which override the scene's `<default>`s.
pub(crate) fn parse(file: &Path, text: &str, defines: &[(String, String)]) -> Result<Element, SceneError> {
    let doc = roxmltree::Document::parse(text).map_err(|e| SceneError {
        file: file.to_path_buf(),
        line: e.pos().row,
        element: "XML".into(),
        message: format!("malformed XML: {e}"),
    })?;
    let root = doc.root_element();
    check_depth(&doc).map_err(|(row, message)| SceneError {
        file: file.to_path_buf(),
        line: row,
        element: "XML".into(),
        message,
    })?;
    let line_of = |n: roxmltree::Node| doc.text_pos_at(n.range().start).row;
    let err = |n: roxmltree::Node, message: String| SceneError {
        file: file.to_path_buf(),
        line: line_of(n),
        element: format!("<{}>", n.tag_name().name()),
        message,
    };
    if root.tag_name().name() != "scene" {
        return Err(err(root, "the root element must be <scene>".into()));
    }
    match root.attribute("version") {
        Some(v) if v.starts_with("3.") || v.starts_with("2.") => {}
        Some(v) => {
            return Err(err(
                root,
                format!("unsupported scene version \"{v}\" (expected 3.x)"),
            ));
        }
        None => {
            return Err(err(
                root,
                "missing the version attribute (e.g. version=\"3.0.0\")".into(),
            ));
        }
    }

    // Parameters: the command line's, then the scene's defaults for those it does not set (in
    // document order, so a default may use an earlier parameter), as Mitsuba does.
    let mut params: HashMap<String, String> = defines.iter().cloned().collect();
    let mut budget = MAX_EXPANSION;
    for n in root
        .children()
        .filter(|n| n.is_element() && n.tag_name().name() == "default")
    {
        let (Some(name), Some(value)) = (n.attribute("name"), n.attribute("value")) else {
            return Err(err(n, "a <default> needs name and value".into()));
        };
        if !params.contains_key(name) {
            let value = substitute(value, &params, &mut budget).map_err(|m| err(n, m))?;
            params.insert(name.to_string(), value);
        }
    }

    fn convert(
        n: roxmltree::Node,
        params: &HashMap<String, String>,
        budget: &mut usize,
        line_of: &dyn Fn(roxmltree::Node) -> u32,
        err: &dyn Fn(roxmltree::Node, String) -> SceneError,
    ) -> Result<Element, SceneError> {
        let mut attrs = Vec::new();
        for a in n.attributes() {
            let v = substitute(a.value(), params, budget).map_err(|m| err(n, m))?;
            attrs.push((a.name().to_string(), v));
        }
        let mut children = Vec::new();
        for c in n.children() {
            if c.is_element() {
                if c.tag_name().name() == "default" {
                    continue;
                }
                children.push(convert(c, params, budget, line_of, err)?);
            } else if c.is_text() && !c.text().unwrap_or("").trim().is_empty() {
                return Err(err(n, "unexpected text inside the element".into()));
            }
        }
        Ok(Element {
            tag: n.tag_name().name().to_string(),
            attrs,
            line: line_of(n),
            children,
        })
    }
    convert(root, &params, &mut budget, &line_of, &err)
}

/// Refuses nesting deeper than [`MAX_DEPTH`], without recursion; returns the line and message.
fn check_depth(doc: &roxmltree::Document) -> Result<(), (u32, String)> {
    // Descendants come in document order, so a node's parent is seen before it.
    let mut depth: Vec<u32> = Vec::new();
    for n in doc.descendants() {
        let d = n.parent().map_or(0, |p| depth[p.id().get_usize()] + 1);
        let i = n.id().get_usize();
        if depth.len() <= i {
            depth.resize(i + 1, 0);
        }
        depth[i] = d;
        if d as usize > MAX_DEPTH {
            return Err((
                doc.text_pos_at(n.range().start).row,
                format!("elements nest deeper than {MAX_DEPTH} levels"),
            ));
        }
    }
    Ok(())
}

/// Replaces every `$name` by its parameter's value, taking what it produces from `budget`.
fn substitute(value: &str, params: &HashMap<String, String>, budget: &mut usize) -> Result<String, String> {
    if !value.contains('$') {
        return Ok(value.to_string());
    }
    let over = || {
        format!(
            "parameter substitution produces more than {MAX_EXPANSION} bytes (defaults that repeat defaults?)"
        )
    };
    let mut out = String::new();
    let mut rest = value;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let len = after
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        let name = &after[..len];
        if name.is_empty() {
            return Err(format!("a lone '$' in \"{value}\""));
        }
        match params.get(name) {
            Some(v) => {
                *budget = budget.checked_sub(v.len()).ok_or_else(over)?;
                out.push_str(v)
            }
            None => {
                return Err(format!(
                    "parameter ${name} has no value: add <default name=\"{name}\" value=\"...\"/> or pass -D {name}=..."
                ));
            }
        }
        rest = &after[len..];
    }
    out.push_str(rest);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn substitutes_defaults_and_overrides() {
        let text = r#"<scene version="3.0.0"><default name="res" value="64"/><default name="w" value="$res"/>
            <film width="$w" height="$res"/></scene>"#;
        let root = parse(Path::new("t.xml"), text, &[("res".into(), "32".into())]).unwrap();
        let film = &root.children[0];
        // The override applies wherever $res is used, defaults built from it included.
        assert_eq!(film.attr("height"), Some("32"));
        assert_eq!(film.attr("width"), Some("32"));
        assert_eq!(film.line, 2);
    }

    #[test]
    fn deep_nesting_is_refused_without_overflowing_the_stack() {
        let depth = 5000;
        let text = format!(
            "<scene version=\"3.0.0\">{}{}</scene>",
            "<a>".repeat(depth),
            "</a>".repeat(depth)
        );
        let e = parse(Path::new("t.xml"), &text, &[]).unwrap_err();
        assert!(e.message.contains("deeper than"), "{e}");
        let ok = format!(
            "<scene version=\"3.0.0\">{}{}</scene>",
            "<a>".repeat(50),
            "</a>".repeat(50)
        );
        assert!(parse(Path::new("t.xml"), &ok, &[]).is_ok());
    }

    #[test]
    fn default_expansion_bombs_are_refused() {
        // Each default doubles the one before: 2^40 bytes if expanded, in a 1 KB file.
        let mut text =
            String::from("<scene version=\"3.0.0\"><default name=\"d0\" value=\"xxxxxxxxxxxxxxxx\"/>");
        for i in 1..40 {
            text.push_str(&format!(
                "<default name=\"d{i}\" value=\"$d{}$d{}\"/>",
                i - 1,
                i - 1
            ));
        }
        text.push_str("</scene>");
        assert!(text.len() < 2048);
        let e = parse(Path::new("t.xml"), &text, &[]).unwrap_err();
        assert!(e.message.contains("more than"), "{e}");
    }

    #[test]
    fn undefined_parameter_is_an_error() {
        let e = parse(
            Path::new("t.xml"),
            r#"<scene version="3.0.0"><a v="$nope"/></scene>"#,
            &[],
        )
        .unwrap_err();
        assert!(e.to_string().contains("$nope"), "{e}");
    }

    #[test]
    fn malformed_xml_names_the_line() {
        let e = parse(
            Path::new("t.xml"),
            "<scene version=\"3.0.0\">\n<a>\n</scene>",
            &[],
        )
        .unwrap_err();
        assert_eq!(e.line, 3, "{e}");
    }
}
