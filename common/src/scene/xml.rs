//! Reads the XML into a small tree with line numbers and `$name` parameters substituted, as
//! Mitsuba 3's parser does: `<default>`s take effect in document order wherever they stand,
//! `<include>` splices in another file (its `<scene>` children, or its one object), `<path>`
//! adds a folder to search for files, and a `-D` parameter that nothing uses is an error.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::SceneError;

/// Mitsuba's limit on nested includes (a cycle of includes stops here too).
const MAX_INCLUDE_DEPTH: u32 = 15;

/// Deepest element nesting accepted, counted across includes. Mitsuba scenes nest a handful of
/// levels; the limit keeps the recursive reading below (and the builders after it) far from the
/// stack's end, also on a worker's smaller thread stacks.
pub(crate) const MAX_DEPTH: u32 = 100;

/// Most bytes `$name` substitution may produce over a whole scene. Parameters may refer to
/// parameters, so a 1 KB file could otherwise ask for gigabytes (an expansion bomb).
pub(crate) const MAX_EXPANSION: usize = 16 << 20;

/// One XML element, with what errors need to point at it.
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub tag: String,
    pub attrs: Vec<(String, String)>,
    /// The file the element was written in (the scene or an included file).
    pub file: Arc<PathBuf>,
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

/// The scene's element tree and what reading it found out about files.
pub(crate) struct Parsed {
    pub root: Element,
    /// `<path>` folders, searched first (the last one given first), before the scene's folder.
    pub search_dirs: Vec<PathBuf>,
    /// Included XML files, as resolved.
    pub includes: Vec<PathBuf>,
}

/// Parses `text` (the contents of `file`); `defines` are the command line's `-D name=value`,
/// which override the scene's `<default>`s.
pub(crate) fn parse(file: &Path, text: &str, defines: &[(String, String)]) -> Result<Parsed, SceneError> {
    let mut reader = Reader {
        enclosing: Vec::new(),
        budget: MAX_EXPANSION,
        params: defines.iter().cloned().collect(),
        used: defines.iter().map(|(k, _)| (k.clone(), false)).collect(),
        search_dirs: Vec::new(),
        includes: Vec::new(),
    };
    let mut roots = reader.file(file, text, 0, true)?;
    let root = roots.pop().expect("the main file gives its root");
    let mut unused: Vec<String> = reader
        .used
        .iter()
        // A sequence sets `frame` on every frame; a scene that does not animate ignores it.
        .filter(|(k, used)| !**used && k.as_str() != crate::frames::FRAME_PARAMETER)
        .map(|(k, _)| format!("{k}={}", reader.params[k]))
        .collect();
    if !unused.is_empty() {
        unused.sort();
        return Err(SceneError {
            file: file.to_path_buf(),
            line: 0,
            element: "-D".into(),
            message: format!(
                "parameters the scene never uses (as $name): {} (Mitsuba refuses these too)",
                unused.join(", ")
            ),
        });
    }
    Ok(Parsed {
        root,
        search_dirs: reader.search_dirs,
        includes: reader.includes,
    })
}

/// Parameters, folders and files gathered across the scene and its includes.
struct Reader {
    /// Folders of the files whose includes are being read, outermost first.
    enclosing: Vec<PathBuf>,
    /// Bytes that `$name` substitution may still produce.
    budget: usize,
    params: HashMap<String, String>,
    /// For each `-D` parameter, whether any `$name` used it.
    used: HashMap<String, bool>,
    search_dirs: Vec<PathBuf>,
    includes: Vec<PathBuf>,
}

impl Reader {
    /// Reads one file: the main scene (`main`, returns its root) or an included file (returns
    /// the elements it contributes).
    fn file(&mut self, file: &Path, text: &str, depth: u32, main: bool) -> Result<Vec<Element>, SceneError> {
        let text = lenient_comments(text);
        let doc = roxmltree::Document::parse(&text).map_err(|e| SceneError {
            file: file.to_path_buf(),
            line: e.pos().row,
            element: "XML".into(),
            message: format!("malformed XML: {e}"),
        })?;
        let src = Arc::new(file.to_path_buf());
        let root = doc.root_element();
        let at = |n: roxmltree::Node, message: String| SceneError {
            file: file.to_path_buf(),
            line: doc.text_pos_at(n.range().start).row,
            element: format!("<{}>", n.tag_name().name()),
            message,
        };
        if main && root.tag_name().name() != "scene" {
            return Err(at(root, "the root element must be <scene>".into()));
        }
        match root.attribute("version") {
            Some(v) if v.split(['.', ' ']).count() == 3 && (v.starts_with("3.") || v.starts_with("2.")) => {}
            Some(v) => {
                return Err(at(
                    root,
                    format!("unsupported scene version \"{v}\" (expected 3.x.y)"),
                ));
            }
            None => {
                return Err(at(
                    root,
                    "missing the version attribute (e.g. version=\"3.0.0\")".into(),
                ));
            }
        }
        check_depth(&doc).map_err(|(line, message)| SceneError {
            file: file.to_path_buf(),
            line,
            element: "XML".into(),
            message,
        })?;
        let ctx = FileCtx {
            lines: Lines::of(&text),
            src,
            depth,
        };
        if root.tag_name().name() == "scene" {
            let children = self.children(&ctx, root, true)?;
            if !main {
                return Ok(children);
            }
            let attrs = root
                .attributes()
                .map(|a| (a.name().to_string(), a.value().to_string()))
                .collect();
            return Ok(vec![Element {
                tag: "scene".into(),
                attrs,
                file: ctx.src.clone(),
                line: ctx.line(root),
                children,
            }]);
        }
        Ok(vec![self.element(&ctx, root)?])
    }

    /// One element and everything below it.
    fn element(&mut self, ctx: &FileCtx, n: roxmltree::Node) -> Result<Element, SceneError> {
        let mut attrs = Vec::new();
        for a in n.attributes() {
            let v = self.substitute(a.value()).map_err(|m| ctx.err(n, m))?;
            attrs.push((a.name().to_string(), v));
        }
        Ok(Element {
            tag: n.tag_name().name().to_string(),
            attrs,
            file: ctx.src.clone(),
            line: ctx.line(n),
            children: self.children(ctx, n, false)?,
        })
    }

    /// The children of `n` in document order, with defaults applied, includes spliced in and
    /// `<path>` folders recorded (`top`: `n` is the scene element).
    fn children(&mut self, ctx: &FileCtx, n: roxmltree::Node, top: bool) -> Result<Vec<Element>, SceneError> {
        let mut out = Vec::new();
        for c in n.children() {
            if c.is_text() {
                if !c.text().unwrap_or("").trim().is_empty() {
                    return Err(ctx.err(n, "unexpected text inside the element".into()));
                }
                continue;
            }
            if !c.is_element() {
                continue;
            }
            match c.tag_name().name() {
                "default" => {
                    let (Some(name), Some(value)) = (c.attribute("name"), c.attribute("value")) else {
                        return Err(ctx.err(c, "a <default> needs name and value".into()));
                    };
                    if name.is_empty() {
                        return Err(ctx.err(c, "a <default> needs a non-empty name".into()));
                    }
                    if !self.params.contains_key(name) {
                        let value = self.substitute(value).map_err(|m| ctx.err(c, m))?;
                        self.params.insert(name.to_string(), value);
                    }
                }
                "path" => {
                    if !top {
                        return Err(ctx.err(c, "<path> can only be a child of the scene".into()));
                    }
                    let value = c
                        .attribute("value")
                        .ok_or_else(|| ctx.err(c, "a <path> needs a value".into()))?;
                    let value = self.substitute(value).map_err(|m| ctx.err(c, m))?;
                    // Relative to the file that says it, else wherever files are searched.
                    let dir = self
                        .search_order(ctx)
                        .into_iter()
                        .map(|d| d.join(&value))
                        .find(|d| d.is_dir())
                        .ok_or_else(|| ctx.err(c, format!("folder \"{value}\" not found")))?;
                    self.search_dirs.insert(0, dir);
                }
                "include" => {
                    let name = c
                        .attribute("filename")
                        .ok_or_else(|| ctx.err(c, "an <include> needs a filename".into()))?;
                    let name = self.substitute(name).map_err(|m| ctx.err(c, m))?;
                    if ctx.depth + 1 > MAX_INCLUDE_DEPTH {
                        return Err(ctx.err(
                            c,
                            format!("includes nest more than {MAX_INCLUDE_DEPTH} deep (do they include each other?)"),
                        ));
                    }
                    let path = self
                        .search_order(ctx)
                        .into_iter()
                        .map(|d| d.join(&name))
                        .find(|p| p.is_file())
                        .ok_or_else(|| ctx.err(c, format!("included file \"{name}\" not found")))?;
                    let text = std::fs::read_to_string(&path)
                        .map_err(|e| ctx.err(c, format!("cannot read {}: {e}", path.display())))?;
                    self.includes.push(path.clone());
                    self.enclosing.push(ctx.dir());
                    let included = self.file(&path, &text, ctx.depth + 1, false);
                    self.enclosing.pop();
                    let mut included = included?;
                    if let Some(prop) = c.attribute("name")
                        && let [one] = included.as_mut_slice()
                    {
                        one.attrs.retain(|(k, _)| k != "name");
                        one.attrs.push(("name".into(), prop.to_string()));
                    }
                    out.extend(included);
                }
                _ => out.push(self.element(ctx, c)?),
            }
        }
        Ok(out)
    }

    /// Where an include or a `<path>` named in the file being read is looked for, as Mitsuba's
    /// nested file resolvers do: that file's folder, then the folders of the files that
    /// included it (innermost first), then the `<path>` folders.
    fn search_order(&self, ctx: &FileCtx) -> Vec<PathBuf> {
        let mut dirs = vec![ctx.dir()];
        dirs.extend(self.enclosing.iter().rev().cloned());
        dirs.extend(self.search_dirs.iter().cloned());
        dirs
    }

    /// Replaces every `$name` by its parameter's value, noting which `-D` parameters are used.
    fn substitute(&mut self, value: &str) -> Result<String, String> {
        let out = substitute(value, &self.params)?;
        if out.len() > value.len() {
            self.budget = self.budget.checked_sub(out.len() - value.len()).ok_or_else(|| {
                format!("parameter substitution produces more than {MAX_EXPANSION} bytes (defaults that repeat defaults?)")
            })?;
        }
        if value.contains('$') {
            for (k, used) in self.used.iter_mut() {
                if !*used && value.contains(&format!("${k}")) {
                    *used = true;
                }
            }
        }
        Ok(out)
    }
}

/// Where a file's lines start, so that every element's line number is a binary search.
///
/// Why: roxmltree's `text_pos_at` counts newlines from the start of the file on every call
/// (its docs: "use only for errors"), which made loading quadratic in the file's size: 100k
/// spheres, 13 MB, took 298 s, 98% of it there (docs/benchmarks.md, "Scene loading").
struct Lines {
    /// Byte offsets of the file's newlines, in order.
    newlines: Vec<usize>,
}

impl Lines {
    fn of(text: &str) -> Lines {
        Lines {
            newlines: text
                .bytes()
                .enumerate()
                .filter(|&(_, b)| b == b'\n')
                .map(|(i, _)| i)
                .collect(),
        }
    }

    /// The 1-based line of byte offset `pos`, as roxmltree counts it: one more than the
    /// newlines before it.
    fn row(&self, pos: usize) -> u32 {
        (self.newlines.partition_point(|&nl| nl < pos) + 1) as u32
    }
}

/// The text with every `-` inside an XML comment made a space, so that comments Mitsuba's
/// parser (pugixml) reads, such as `<!-- a -- b -->` or `<!-- x --->`, are read here too:
/// XML forbids `--` in a comment and roxmltree holds to it. A comment ends at its first `-->`,
/// as in pugixml; CDATA sections are left alone. Byte offsets do not move, so line numbers
/// stay those of the file as written.
fn lenient_comments(text: &str) -> Cow<'_, str> {
    let mut bytes: Option<Vec<u8>> = None;
    let src = text.as_bytes();
    let mut i = 0;
    while let Some(at) = text[i..].find('<').map(|k| i + k) {
        let rest = &text[at..];
        if let Some(body) = rest.strip_prefix("<!--") {
            let start = at + 4;
            let end = body.find("-->").map_or(src.len(), |k| start + k);
            if src[start..end].contains(&b'-') {
                let out = bytes.get_or_insert_with(|| src.to_vec());
                for b in &mut out[start..end] {
                    if *b == b'-' {
                        *b = b' ';
                    }
                }
            }
            i = (end + 3).min(src.len());
        } else if rest.starts_with("<![CDATA[") {
            i = rest.find("]]>").map_or(src.len(), |k| at + k + 3);
        } else {
            i = at + 1;
        }
    }
    match bytes {
        // Only ASCII '-' bytes were replaced by ASCII spaces, so the text is still UTF-8.
        Some(b) => Cow::Owned(String::from_utf8(b).expect("ASCII replaced by ASCII")),
        None => Cow::Borrowed(text),
    }
}

/// Refuses nesting deeper than [`MAX_DEPTH`] in one file, without recursion (so before anything
/// recurses); returns the line and message. Includes add their depth to the including
/// element's, which [`MAX_INCLUDE_DEPTH`] bounds.
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
        if d > MAX_DEPTH {
            return Err((
                doc.text_pos_at(n.range().start).row,
                format!("elements nest deeper than {MAX_DEPTH} levels"),
            ));
        }
    }
    Ok(())
}

/// The file being read, for errors and relative paths.
struct FileCtx {
    lines: Lines,
    src: Arc<PathBuf>,
    depth: u32,
}

impl FileCtx {
    fn line(&self, n: roxmltree::Node) -> u32 {
        self.lines.row(n.range().start)
    }

    fn err(&self, n: roxmltree::Node, message: String) -> SceneError {
        SceneError {
            file: self.src.to_path_buf(),
            line: self.line(n),
            element: format!("<{}>", n.tag_name().name()),
            message,
        }
    }

    /// The folder of the file being read: includes and `<path>`s are relative to it.
    fn dir(&self) -> PathBuf {
        self.src
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf()
    }
}

/// Replaces every `$name` by its parameter's value.
fn substitute(value: &str, params: &HashMap<String, String>) -> Result<String, String> {
    if !value.contains('$') {
        return Ok(value.to_string());
    }
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
                if out.len() + v.len() > MAX_EXPANSION {
                    return Err(format!(
                        "parameter substitution produces more than {MAX_EXPANSION} bytes (defaults that repeat defaults?)"
                    ));
                }
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
        let root = parse(Path::new("t.xml"), text, &[("res".into(), "32".into())])
            .unwrap()
            .root;
        let film = &root.children[0];
        // The override applies wherever $res is used, defaults built from it included.
        assert_eq!(film.attr("height"), Some("32"));
        assert_eq!(film.attr("width"), Some("32"));
        assert_eq!(film.line, 2);
    }

    #[test]
    fn undefined_parameter_is_an_error() {
        let e = parse(
            Path::new("t.xml"),
            r#"<scene version="3.0.0"><a v="$nope"/></scene>"#,
            &[],
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("$nope"), "{e}");
    }

    #[test]
    fn deep_nesting_is_refused_without_overflowing_the_stack() {
        let depth = 5000;
        let text = format!(
            "<scene version=\"3.0.0\">{}{}</scene>",
            "<a>".repeat(depth),
            "</a>".repeat(depth)
        );
        let e = parse(Path::new("t.xml"), &text, &[]).err().unwrap();
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
        let e = parse(Path::new("t.xml"), &text, &[]).err().unwrap();
        assert!(e.message.contains("more than"), "{e}");
    }

    #[test]
    fn an_unused_define_is_an_error_and_defaults_follow_document_order() {
        let text = r#"<scene version="3.0.0"><a v="1"/></scene>"#;
        let e = parse(Path::new("t.xml"), text, &[("res".into(), "8".into())])
            .err()
            .unwrap();
        assert!(e.to_string().contains("res=8"), "{e}");
        // A default applies from where it stands, also nested, and a later one does not override.
        let text = r#"<scene version="3.0.0"><b><default name="x" value="2"/></b>
            <default name="x" value="3"/><a v="$x"/></scene>"#;
        let root = parse(Path::new("t.xml"), text, &[]).unwrap().root;
        assert_eq!(root.children[1].attr("v"), Some("2"));
        let e = parse(
            Path::new("t.xml"),
            r#"<scene version="3.0.0"><a v="$y"/><default name="y" value="1"/></scene>"#,
            &[],
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("$y"), "{e}");
    }

    #[test]
    fn malformed_xml_names_the_line() {
        let e = parse(
            Path::new("t.xml"),
            "<scene version=\"3.0.0\">\n<a>\n</scene>",
            &[],
        )
        .err()
        .unwrap();
        assert_eq!(e.line, 3, "{e}");
    }

    #[test]
    fn line_numbers_are_roxmltrees_at_every_offset() {
        let text = "<scene version=\"3.0.0\">\n\n  <a/>\r\n<b>\n</b>\n</scene>\n";
        let doc = roxmltree::Document::parse(text).unwrap();
        let lines = Lines::of(text);
        for pos in 0..=text.len() {
            assert_eq!(lines.row(pos), doc.text_pos_at(pos).row, "offset {pos}");
        }
    }

    #[test]
    fn comments_with_double_dashes_are_read_as_mitsuba_reads_them() {
        // pugixml (Mitsuba's parser) takes these; the XML specification and roxmltree do not.
        let text = "<scene version=\"3.0.0\">\n<!-- exported -- by a tool --->\n<!---- rule ---->\n<film width=\"3--\"/>\n</scene>";
        assert!(roxmltree::Document::parse(text).is_err());
        let root = parse(Path::new("t.xml"), text, &[]).unwrap().root;
        let film = &root.children[0];
        // Dashes outside comments (an attribute, CDATA) are kept, and lines do not move.
        assert_eq!(film.attr("width"), Some("3--"));
        assert_eq!(film.line, 4);
        assert_eq!(
            lenient_comments("<a><![CDATA[<!-- -- ]]></a>"),
            "<a><![CDATA[<!-- -- ]]></a>"
        );
        // A comment that never ends is still an error, on the comment's line.
        let e = parse(
            Path::new("t.xml"),
            "<scene version=\"3.0.0\">\n<!-- -- \n</scene>",
            &[],
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("malformed XML"), "{e}");
    }
}
