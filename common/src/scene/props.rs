//! Typed access to an element's parameters, with every parameter accounted for: whatever a
//! builder does not read is an error, never silently ignored.

use std::cell::Cell;
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3A};

use super::SceneError;
use super::spectrum::{self, SpectrumUse};
use super::transform::parse_transform;
use super::xml::Element;
use crate::color::Rgb;

/// Where a scene's files may come from.
#[derive(Clone, Debug)]
pub enum FileRoot {
    /// Anywhere, as Mitsuba resolves them: a local render of the user's own files.
    Anywhere,
    /// Only inside this folder (a job bundle's): a farm never reads outside a bundle.
    Inside(PathBuf),
}

/// The scene file, the folders that file names are resolved in, and where files may come from.
pub(crate) struct Ctx {
    pub file: PathBuf,
    pub dir: PathBuf,
    /// `<path>` folders, searched before the scene's folder.
    pub search_dirs: Vec<PathBuf>,
    pub root: FileRoot,
    /// Every file resolved so far (meshes, spectra): what a job's bundle must carry.
    pub files: std::cell::RefCell<Vec<PathBuf>>,
}

impl Ctx {
    pub fn err(&self, el: &Element, message: impl Into<String>) -> SceneError {
        SceneError {
            file: el.file.to_path_buf(),
            line: el.line,
            element: el.describe(),
            message: message.into(),
        }
    }
}

const VALUE_TAGS: &[&str] = &[
    "float",
    "integer",
    "boolean",
    "string",
    "rgb",
    "point",
    "vector",
    "spectrum",
    "transform",
];

/// Mitsuba's `xyz_to_srgb(Color3f(1))`: the linear sRGB colour of a flat spectrum of value 1.
const FLAT_SPECTRUM_RGB: Rgb = Rgb::new(1.204_794, 0.948_291, 0.908_916);

/// The parameters and nested objects of one element.
pub(crate) struct Props<'a> {
    pub ctx: &'a Ctx,
    pub el: &'a Element,
    values: Vec<(&'a str, &'a Element, Cell<bool>)>,
    objects: Vec<(&'a Element, Cell<bool>)>,
}

pub(crate) type Res<T> = Result<T, SceneError>;

impl<'a> Props<'a> {
    pub fn new(ctx: &'a Ctx, el: &'a Element) -> Res<Props<'a>> {
        let mut values = Vec::new();
        let mut objects = Vec::new();
        for c in &el.children {
            if VALUE_TAGS.contains(&c.tag.as_str()) {
                let Some(name) = c.attr("name") else {
                    return Err(ctx.err(c, "a parameter needs a name attribute"));
                };
                if values.iter().any(|(n, _, _)| *n == name) {
                    return Err(ctx.err(c, format!("parameter '{name}' is given twice")));
                }
                values.push((name, c, Cell::new(false)));
            } else {
                objects.push((c, Cell::new(false)));
            }
        }
        Ok(Props {
            ctx,
            el,
            values,
            objects,
        })
    }

    /// The element's `type` attribute.
    pub fn kind(&self) -> Res<&'a str> {
        self.el
            .attr("type")
            .ok_or_else(|| self.ctx.err(self.el, "missing the type attribute"))
    }

    /// The tag a parameter was given with, for parameters that accept several kinds.
    pub fn tag_of(&self, name: &str) -> Option<&'a str> {
        self.values
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|(_, el, _)| el.tag.as_str())
    }

    fn take(&self, name: &str, tags: &[&str]) -> Res<Option<&'a Element>> {
        let Some((_, el, used)) = self.values.iter().find(|(n, _, _)| *n == name) else {
            return Ok(None);
        };
        if !tags.contains(&el.tag.as_str()) {
            let want: Vec<String> = tags.iter().map(|t| format!("<{t}>")).collect();
            return Err(self.ctx.err(
                el,
                format!("parameter '{name}' must be given as {}", want.join(" or ")),
            ));
        }
        used.set(true);
        Ok(Some(el))
    }

    fn value_attr(&self, el: &'a Element) -> Res<&'a str> {
        el.attr("value")
            .ok_or_else(|| self.ctx.err(el, "missing the value attribute"))
    }

    pub fn parse_f32(&self, el: &Element, s: &str) -> Res<f32> {
        let v: f32 = s
            .trim()
            .parse()
            .map_err(|_| self.ctx.err(el, format!("\"{s}\" is not a number")))?;
        if !v.is_finite() {
            return Err(self.ctx.err(el, format!("\"{s}\" is not a finite number")));
        }
        Ok(v)
    }

    pub fn parse_list(&self, el: &Element, s: &str) -> Res<Vec<f32>> {
        s.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| self.parse_f32(el, t))
            .collect()
    }

    pub fn float(&self, name: &str) -> Res<Option<f32>> {
        match self.take(name, &["float", "integer"])? {
            Some(el) => Ok(Some(self.parse_f32(el, self.value_attr(el)?)?)),
            None => Ok(None),
        }
    }

    pub fn float_or(&self, name: &str, default: f32) -> Res<f32> {
        Ok(self.float(name)?.unwrap_or(default))
    }

    /// A number that Mitsuba reads through a texture's `eval_1` (a mask's opacity, a blend's
    /// weight, the principled weights): a `<float>`, or an `<rgb>`, which Mitsuba holds as an
    /// `srgb` reflectance (channels in [0, 1]) and evaluates as the mean of its channels.
    pub fn float_of_texture(&self, name: &str, default: f32) -> Res<f32> {
        if self.tag_of(name) == Some("rgb") {
            let c = self.reflectance(name, Rgb::ZERO)?;
            return Ok((c.x + c.y + c.z) / 3.0);
        }
        self.float_or(name, default)
    }

    /// A float that must be > 0.
    pub fn positive(&self, name: &str, default: f32) -> Res<f32> {
        let v = self.float_or(name, default)?;
        if v <= 0.0 {
            return Err(self.err_at(name, format!("'{name}' must be positive, not {v}")));
        }
        Ok(v)
    }

    pub fn int(&self, name: &str) -> Res<Option<i64>> {
        match self.take(name, &["integer"])? {
            Some(el) => {
                let s = self.value_attr(el)?;
                s.trim()
                    .parse()
                    .map(Some)
                    .map_err(|_| self.ctx.err(el, format!("\"{s}\" is not an integer")))
            }
            None => Ok(None),
        }
    }

    pub fn boolean(&self, name: &str) -> Res<Option<bool>> {
        match self.take(name, &["boolean"])? {
            Some(el) => match self.value_attr(el)?.trim() {
                "true" | "1" => Ok(Some(true)),
                "false" | "0" => Ok(Some(false)),
                s => Err(self.ctx.err(el, format!("\"{s}\" is not true or false"))),
            },
            None => Ok(None),
        }
    }

    pub fn string(&self, name: &str) -> Res<Option<&'a str>> {
        match self.take(name, &["string"])? {
            Some(el) => Ok(Some(self.value_attr(el)?)),
            None => Ok(None),
        }
    }

    /// A colour that is not a reflectance or an emission (conductors' `eta` and `k`, media):
    /// `<rgb>`, `<float>` or `<spectrum>` (a single value is grey; lists and `.spd` files are
    /// converted as Mitsuba's RGB variants do, D65-weighted, negatives clipped).
    pub fn rgb(&self, name: &str) -> Res<Option<Rgb>> {
        self.color(name, SpectrumUse::Unbounded)
    }

    fn color(&self, name: &str, use_: SpectrumUse) -> Res<Option<Rgb>> {
        let Some(el) = self.take(name, &["rgb", "spectrum", "float"])? else {
            return Ok(None);
        };
        if el.tag == "spectrum" {
            let (wavelengths, values) = match (el.attr("filename"), el.attr("value")) {
                (Some(f), None) => {
                    let path = self.resolve_file_of(el, f)?;
                    spectrum::read_spd(&path)
                        .map_err(|m| self.ctx.err(el, format!("{}: {m}", path.display())))?
                }
                (None, Some(v)) if v.contains(':') => {
                    spectrum::parse_list(v).map_err(|m| self.ctx.err(el, m))?
                }
                (None, Some(v)) => {
                    // A flat spectrum: grey, except as emitted light (see `emission`).
                    let g = self.parse_f32(el, v)?;
                    let flat = if use_ == SpectrumUse::Emission {
                        FLAT_SPECTRUM_RGB
                    } else {
                        Rgb::ONE
                    };
                    return Ok(Some(flat * g));
                }
                _ => {
                    return Err(self
                        .ctx
                        .err(el, "a <spectrum> needs a value or a filename, not both"));
                }
            };
            return Ok(Some(spectrum::to_rgb(&wavelengths, &values, use_)));
        }
        let s = self.value_attr(el)?;
        let v = self.parse_list(el, s)?;
        match v.as_slice() {
            [g] => Ok(Some(Rgb::splat(*g))),
            [r, g, b] if el.tag == "rgb" => Ok(Some(Rgb::new(*r, *g, *b))),
            _ => Err(self
                .ctx
                .err(el, format!("expected one or three numbers, got \"{s}\""))),
        }
    }

    /// A colour with every channel in [0, 1]: a reflectance cannot create energy. Spectra are
    /// weighted by D65 and clamped into range, as Mitsuba does.
    pub fn reflectance(&self, name: &str, default: Rgb) -> Res<Rgb> {
        let v = self.color(name, SpectrumUse::Reflectance)?.unwrap_or(default);
        if v.min_element() < 0.0 || v.max_element() > 1.0 {
            return Err(self.err_at(name, format!("'{name}' must lie in [0, 1], not {v}")));
        }
        Ok(v)
    }

    /// Emitted light (radiance, intensity): a colour with no negative channel. Spectra are not
    /// weighted by D65, and a single-valued `<spectrum>` is a flat spectrum, whose colour in
    /// Mitsuba's RGB variants is not grey: v · xyz_to_srgb(1, 1, 1).
    pub fn emission(&self, name: &str, default: Rgb) -> Res<Rgb> {
        let v = self.color(name, SpectrumUse::Emission)?.unwrap_or(default);
        if v.min_element() < 0.0 {
            return Err(self.err_at(name, format!("'{name}' cannot be negative: {v}")));
        }
        Ok(v)
    }

    /// A colour with no negative channel.
    pub fn non_negative_rgb(&self, name: &str, default: Rgb) -> Res<Rgb> {
        let v = self.rgb(name)?.unwrap_or(default);
        if v.min_element() < 0.0 {
            return Err(self.err_at(name, format!("'{name}' cannot be negative: {v}")));
        }
        Ok(v)
    }

    /// A `<point>` or `<vector>`: x, y, z attributes or a value list.
    pub fn point(&self, name: &str) -> Res<Option<Vec3A>> {
        let Some(el) = self.take(name, &["point", "vector"])? else {
            return Ok(None);
        };
        if let Some(s) = el.attr("value") {
            let v = self.parse_list(el, s)?;
            return match v.as_slice() {
                [x, y, z] => Ok(Some(Vec3A::new(*x, *y, *z))),
                _ => Err(self.ctx.err(el, format!("expected three numbers, got \"{s}\""))),
            };
        }
        let c = |k: &str| el.attr(k).map(|s| self.parse_f32(el, s)).unwrap_or(Ok(0.0));
        Ok(Some(Vec3A::new(c("x")?, c("y")?, c("z")?)))
    }

    pub fn transform(&self, name: &str) -> Res<Option<Mat4>> {
        match self.take(name, &["transform"])? {
            Some(el) => parse_transform(self, el).map(Some),
            None => Ok(None),
        }
    }

    /// Nested elements with this tag (objects such as `<bsdf>` or `<emitter>`).
    pub fn objects(&self, tag: &str) -> Vec<&'a Element> {
        self.objects
            .iter()
            .filter(|(el, _)| el.tag == tag)
            .map(|(el, used)| {
                used.set(true);
                *el
            })
            .collect()
    }

    /// The nested element with this tag and `name` attribute (a texture given for a
    /// parameter), if any.
    pub fn named_object(&self, tag: &str, name: &str) -> Option<&'a Element> {
        let (el, used) = self
            .objects
            .iter()
            .find(|(el, _)| el.tag == tag && el.attr("name") == Some(name))?;
        used.set(true);
        Some(*el)
    }

    /// At most one nested element with this tag.
    pub fn object(&self, tag: &str) -> Res<Option<&'a Element>> {
        let all = self.objects(tag);
        if all.len() > 1 {
            return Err(self.ctx.err(all[1], format!("only one <{tag}> is allowed here")));
        }
        Ok(all.first().copied())
    }

    /// An error at the named parameter's line (or the element's if it was defaulted).
    pub fn err_at(&self, name: &str, message: String) -> SceneError {
        match self.values.iter().find(|(n, _, _)| *n == name) {
            Some((_, el, _)) => self.ctx.err(el, message),
            None => self.ctx.err(self.el, message),
        }
    }

    /// Fails on the first parameter or nested element that nothing read.
    pub fn finish(&self) -> Res<()> {
        if let Some((name, el, _)) = self.values.iter().find(|(_, _, used)| !used.get()) {
            return Err(self.ctx.err(
                el,
                format!(
                    "unknown parameter '{name}' for {} (not supported)",
                    self.el.describe()
                ),
            ));
        }
        if let Some((el, _)) = self.objects.iter().find(|(_, used)| !used.get()) {
            return Err(self.ctx.err(
                el,
                format!("<{}> is not supported inside {}", el.tag, self.el.describe()),
            ));
        }
        Ok(())
    }

    /// Resolves a file name (parameter `param`) as Mitsuba does: the `<path>` folders (the
    /// last given first), then the scene's folder; absolute names and `..` are allowed. Inside
    /// a bundle the file must also lie inside the bundle's folder, links followed.
    pub fn resolve_file(&self, param: &str, name: &str) -> Res<PathBuf> {
        let el = self
            .values
            .iter()
            .find(|(n, _, _)| *n == param)
            .map_or(self.el, |(_, el, _)| *el);
        self.resolve_file_of(el, name)
    }

    /// [`Props::resolve_file`] for a file named by element `el`; records it as a file the
    /// scene reads.
    fn resolve_file_of(&self, el: &Element, name: &str) -> Res<PathBuf> {
        let candidates: Vec<PathBuf> = if Path::new(name).is_absolute() {
            vec![PathBuf::from(name)]
        } else {
            self.ctx
                .search_dirs
                .iter()
                .chain(std::iter::once(&self.ctx.dir))
                .map(|d| d.join(name))
                .collect()
        };
        let Some(found) = candidates.iter().find(|p| p.is_file()) else {
            let searched: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            return Err(self.ctx.err(
                el,
                format!("file \"{name}\" not found (looked for {})", searched.join(", ")),
            ));
        };
        let real = found
            .canonicalize()
            .map_err(|e| self.ctx.err(el, format!("{}: {e}", found.display())))?;
        if let FileRoot::Inside(root) = &self.ctx.root {
            let inside = root.canonicalize().is_ok_and(|r| real.starts_with(r));
            if !inside {
                return Err(self
                    .ctx
                    .err(el, format!("file \"{name}\" resolves outside the job's bundle")));
            }
        }
        self.ctx.files.borrow_mut().push(real.clone());
        Ok(real)
    }
}
