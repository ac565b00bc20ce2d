//! An image part as an OpenEXR file: the pixels of a window of an image, placed in it the
//! format's own way, with what they were rendered from.
//!
//! The file's *display window* is the whole image and its *data window* the part (OpenEXR's
//! way to say "this is a region of that image"; a whole image has the two equal). One header
//! attribute, `raypack`, records the [`Provenance`]: the scene (its file name and a digest of
//! its committed contents), the camera and every setting a pixel's value depends on, so that
//! parts of different renders are refused when merged ([`super::merge`]). Pixels are linear
//! 32-bit float RGB, ZIP-compressed scan lines in increasing order, written on one thread: the
//! bytes of a file are a function of its pixels and provenance alone, so the parts of any split
//! merge into the very file a whole render writes.

use super::{Film, PixelBounds, RenderSettings};
use crate::math::Vec3;
use crate::scene::{Camera, Scene};

/// Name of the header attribute holding the [`Provenance`].
pub const ATTRIBUTE: &str = "raypack";

/// Version of the provenance record (its first field).
pub const PROVENANCE_VERSION: &str = "1";

/// Largest image side a part may claim (as `raypack render -r` allows).
pub const MAX_SIDE: usize = 1 << 15;

/// What a part's pixels are a function of: `key=value` fields in a fixed order. The keys
/// `scene` and `scene-digest` name the scene; the others are the camera and the settings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Provenance {
    /// The fields, in order; values are printable ASCII (see [`Provenance::to_text`]).
    pub fields: Vec<(String, String)>,
}

impl Provenance {
    /// The provenance of a render of `scene` (named `scene_name`, for people) through `camera`
    /// with `settings`, plus `extra` fields the caller's pixels also depend on (the BVH's
    /// build options, say).
    pub fn new(
        scene_name: &str,
        scene: &Scene,
        camera: &Camera,
        settings: &RenderSettings,
        extra: &[(&str, String)],
    ) -> Self {
        let mut fields = vec![
            ("raypack".to_string(), PROVENANCE_VERSION.to_string()),
            ("scene".to_string(), scene_name.to_string()),
            ("scene-digest".to_string(), format!("{:032x}", scene_digest(scene))),
            ("camera".to_string(), camera_text(camera)),
        ];
        fields.extend(settings_fields(settings));
        fields.extend(extra.iter().map(|(k, v)| (k.to_string(), v.clone())));
        for (_, v) in &mut fields {
            *v = escape(v);
        }
        Self { fields }
    }

    /// The value of `key`, if present.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// True for the keys that say which scene was rendered.
    pub fn is_scene_key(key: &str) -> bool {
        matches!(key, "scene" | "scene-digest")
    }

    /// One `key=value` line per field.
    pub fn to_text(&self) -> String {
        self.fields.iter().map(|(k, v)| format!("{k}={v}\n")).collect()
    }

    /// Parses [`Provenance::to_text`]'s output.
    pub fn from_text(text: &str) -> Result<Self, String> {
        let mut fields = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let Some((k, v)) = line.split_once('=') else {
                return Err(format!("line {} of the `{ATTRIBUTE}` attribute is not key=value", n + 1));
            };
            fields.push((k.to_string(), v.to_string()));
        }
        if fields.first().is_none_or(|(k, v)| k != "raypack" || v != PROVENANCE_VERSION) {
            return Err(format!("the `{ATTRIBUTE}` attribute is not a version {PROVENANCE_VERSION} provenance record"));
        }
        Ok(Self { fields })
    }

    /// The fields whose values differ, or that only one of the two has: `(key, self's value,
    /// other's value)`, `None` for a missing field.
    pub fn differences<'a>(&'a self, other: &'a Self) -> Vec<(&'a str, Option<&'a str>, Option<&'a str>)> {
        let mut out = Vec::new();
        for (k, v) in &self.fields {
            let o = other.get(k);
            if o != Some(v.as_str()) {
                out.push((k.as_str(), Some(v.as_str()), o));
            }
        }
        for (k, v) in &other.fields {
            if self.get(k).is_none() {
                out.push((k.as_str(), None, Some(v.as_str())));
            }
        }
        out
    }
}

/// Printable ASCII, with `%`, control and non-ASCII bytes as `%XX` (the record is one line
/// per field, and EXR text attributes are bytes).
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if (0x20..0x7f).contains(&b) && b != b'%' {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// The settings a pixel's value depends on, as fields. Every field of [`RenderSettings`] is
/// named here: a new one must be added or said not to change pixels.
fn settings_fields(s: &RenderSettings) -> Vec<(String, String)> {
    let RenderSettings {
        width,
        height,
        samples_per_pixel,
        light_samples,
        max_depth,
        hemisphere_sampling,
        adaptive,
        integrator,
        seed,
        sampler,
        brute_force,
        russian_roulette,
        max_sample_value,
        // The image is the same, bit for bit, whatever the stream order and with or without
        // culling (tests/render_wavefront.rs).
        stream_order: _,
        pixel_culling: _,
        // Parts are rendered by the path tracer only (the heatmap renders whole images).
        heatmap: _,
    } = s;
    let adaptive = adaptive.map_or("off".to_string(), |(b, t)| format!("{b} {t:?}"));
    let clamp = max_sample_value.map_or("off".to_string(), |v| format!("{v:?}"));
    [
        ("width", width.to_string()),
        ("height", height.to_string()),
        ("samples-per-pixel", samples_per_pixel.to_string()),
        ("light-samples", light_samples.to_string()),
        ("max-depth", max_depth.to_string()),
        ("hemisphere-sampling", hemisphere_sampling.to_string()),
        ("adaptive", adaptive),
        ("integrator", integrator.name().to_string()),
        ("seed", seed.to_string()),
        ("sampler", sampler.name().to_string()),
        ("brute-force", brute_force.to_string()),
        ("russian-roulette", russian_roulette.to_string()),
        ("clamp", clamp),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// The camera's every number, exactly (`{:?}` prints the shortest text that reads back to
/// the same float).
fn camera_text(c: &Camera) -> String {
    let v = |v: Vec3| format!("{:?} {:?} {:?}", v.x, v.y, v.z);
    format!(
        "position {} right {} up {} back {} hfov {:?} vfov {:?} near {:?} far {:?}",
        v(c.position),
        v(c.c2w.x_axis),
        v(c.c2w.y_axis),
        v(c.c2w.z_axis),
        c.hfov_deg,
        c.vfov_deg,
        c.near,
        c.far
    )
}

/// XXH3-128 of everything of `scene` that shading reads: geometry, shading normals, material
/// ids, materials and lights (the camera is recorded apart).
pub fn scene_digest(scene: &Scene) -> u128 {
    use xxhash_rust::xxh3::Xxh3;
    let mut h = Xxh3::new();
    let t = &scene.triangles;
    let s = &scene.spheres;
    for bytes in [
        bytemuck::cast_slice::<_, u8>(&t.positions),
        bytemuck::cast_slice(&t.normals),
        bytemuck::cast_slice(&t.indices),
        bytemuck::cast_slice(&t.material),
        bytemuck::cast_slice(&s.center),
        bytemuck::cast_slice(&s.radius),
        bytemuck::cast_slice(&s.material),
        format!("{:?}", scene.materials).as_bytes(),
        format!("{:?}", scene.lights).as_bytes(),
    ] {
        h.update(&(bytes.len() as u64).to_le_bytes());
        h.update(bytes);
    }
    h.digest128()
}

/// Why bytes are not an image part raypack wrote.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// Not a readable OpenEXR file.
    #[error("not a readable OpenEXR file: {0}")]
    Exr(String),
    /// An OpenEXR file, but not one raypack's `render` wrote.
    #[error("{0}")]
    NotAPart(String),
}

/// The pixels of a window of an image and what they were rendered from.
#[derive(Clone, Debug, PartialEq)]
pub struct ImagePart {
    /// Width of the whole image.
    pub width: usize,
    /// Height of the whole image.
    pub height: usize,
    /// Where the part lies in the whole image.
    pub window: PixelBounds,
    /// The part's pixels (`window.width() × window.height()`).
    pub film: Film,
    /// What the pixels were rendered from.
    pub provenance: Provenance,
}

#[cfg(feature = "image")]
impl ImagePart {
    /// The file's bytes (see the module docs).
    pub fn encode_exr(&self) -> Result<Vec<u8>, String> {
        use exr::prelude::*;
        let (w, h) = (self.window.width(), self.window.height());
        if self.film.width != w || self.film.height != h || self.film.pixels.len() != w * h {
            return Err(format!("the film is {}x{}, the window {w}x{h}", self.film.width, self.film.height));
        }
        if self.window.within(self.width, self.height).is_err() || self.width > MAX_SIDE || self.height > MAX_SIDE {
            return Err(format!("window {} is not inside a {}x{} image", self.window, self.width, self.height));
        }
        let text = Text::new_or_none(self.provenance.to_text())
            .ok_or_else(|| "the provenance record is not printable ASCII".to_string())?;
        let mut layer_attributes =
            LayerAttributes::default().with_position(Vec2(self.window.x0 as i32, self.window.y0 as i32));
        layer_attributes.software_name = Some(Text::from(concat!("raypack ", env!("CARGO_PKG_VERSION"))));
        layer_attributes.other.insert(Text::from(ATTRIBUTE), AttributeValue::Text(text));
        let encoding =
            Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };
        let film = &self.film;
        let layer = Layer::new(
            (w, h),
            layer_attributes,
            encoding,
            SpecificChannels::rgb(|p: Vec2<usize>| {
                let c = film.pixels[p.1 * w + p.0];
                (c.x, c.y, c.z)
            }),
        );
        let display = IntegerBounds::from_dimensions((self.width, self.height));
        let image = Image::new(ImageAttributes::new(display), layer);
        let mut buf = std::io::Cursor::new(Vec::new());
        // One thread: the chunks go out in order whatever the scheduling.
        image.write().non_parallel().to_buffered(&mut buf).map_err(|e| e.to_string())?;
        Ok(buf.into_inner())
    }

    /// Reads a part from a file's bytes, checking that raypack wrote it: one layer of 32-bit
    /// float R, G, B, a display window at the origin of at most [`MAX_SIDE`] pixels a side
    /// holding the data window, and a provenance record whose size is the display window's.
    pub fn decode_exr(bytes: &[u8]) -> Result<Self, PartError> {
        let header = PartHeader::read(bytes)?;
        let (w, h) = (header.window.width(), header.window.height());
        let pixels = guard(|| {
            use exr::prelude::*;
            let image = read()
                .no_deep_data()
                .largest_resolution_level()
                .rgb_channels(
                    |_, _| vec![Vec3::ZERO; w * h],
                    move |pixels: &mut Vec<Vec3>, p: Vec2<usize>, (r, g, b): (f32, f32, f32)| {
                        if p.0 < w && p.1 < h {
                            pixels[p.1 * w + p.0] = Vec3::new(r, g, b);
                        }
                    },
                )
                .first_valid_layer()
                .all_attributes()
                .from_buffered(std::io::Cursor::new(bytes))
                .map_err(|e| PartError::Exr(e.to_string()))?;
            Ok(image.layer_data.channel_data.pixels)
        })?;
        if pixels.len() != w * h {
            return Err(PartError::Exr(format!("{} pixels decoded for a {w}x{h} data window", pixels.len())));
        }
        let PartHeader { width, height, window, provenance } = header;
        Ok(Self { width, height, window, film: Film { width: w, height: h, pixels }, provenance })
    }
}

/// What a part's header says: enough to check its size before its pixels are decoded.
#[derive(Clone, Debug, PartialEq)]
pub struct PartHeader {
    /// Width of the whole image.
    pub width: usize,
    /// Height of the whole image.
    pub height: usize,
    /// Where the part lies in the whole image.
    pub window: PixelBounds,
    /// What the pixels were rendered from.
    pub provenance: Provenance,
}

/// Runs third-party decoding code on someone's file: a panic in it is an error in the file,
/// not a crash.
#[cfg(feature = "image")]
fn guard<T>(f: impl FnOnce() -> Result<T, PartError>) -> Result<T, PartError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err(PartError::Exr("the OpenEXR decoder failed on it".into())))
}

#[cfg(feature = "image")]
impl PartHeader {
    /// The header of a part's file (see [`ImagePart::decode_exr`] for what is checked).
    pub fn read(bytes: &[u8]) -> Result<Self, PartError> {
        guard(|| Self::read_checked(bytes))
    }

    fn read_checked(bytes: &[u8]) -> Result<Self, PartError> {
        use exr::prelude::*;
        let not_part = |m: String| PartError::NotAPart(m);
        let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
            .map_err(|e| PartError::Exr(e.to_string()))?;
        let [header] = &meta.headers[..] else {
            return Err(not_part(format!("has {} layers; raypack writes one", meta.headers.len())));
        };
        if header.deep {
            return Err(not_part("holds deep data; raypack writes flat images".into()));
        }
        let channels: Vec<(String, SampleType)> =
            header.channels.list.iter().map(|c| (c.name.to_string(), c.sample_type)).collect();
        let rgb = ["B", "G", "R"].map(|n| (n.to_string(), SampleType::F32));
        if channels != rgb {
            let names: Vec<String> = channels.iter().map(|(n, t)| format!("{n} ({t:?})")).collect();
            return Err(not_part(format!(
                "has channels {}; raypack writes R, G, B as 32-bit floats",
                names.join(", ")
            )));
        }
        let display = header.shared_attributes.display_window;
        let (width, height) = (display.size.0, display.size.1);
        if display.position != Vec2(0, 0) || width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(not_part(format!(
                "display window at ({}, {}) of {width}x{height}; raypack writes images at (0, 0) of 1 to {MAX_SIDE} pixels a side",
                display.position.0, display.position.1
            )));
        }
        let data = header.data_window();
        let (x0, y0) = (data.position.0, data.position.1);
        let window = if x0 < 0 || y0 < 0 {
            None
        } else {
            let (x0, y0) = (x0 as usize, y0 as usize);
            PixelBounds { x0, x1: x0 + data.size.0, y0, y1: y0 + data.size.1 }.within(width, height).ok()
        };
        let Some(window) = window else {
            return Err(not_part(format!(
                "data window at ({x0}, {y0}) of {}x{} is not inside its {width}x{height} display window",
                data.size.0, data.size.1
            )));
        };
        let text = match header.own_attributes.other.get(&Text::from(ATTRIBUTE)) {
            Some(AttributeValue::Text(t)) => t.to_string(),
            Some(_) => return Err(not_part(format!("its `{ATTRIBUTE}` attribute is not text"))),
            None => {
                return Err(not_part(format!(
                    "has no `{ATTRIBUTE}` attribute: it was not written by `raypack render` (or by this version)"
                )));
            }
        };
        let provenance = Provenance::from_text(&text).map_err(not_part)?;
        let size = (provenance.get("width"), provenance.get("height"));
        if size != (Some(width.to_string().as_str()), Some(height.to_string().as_str())) {
            return Err(not_part(format!(
                "its provenance says {}x{} but its display window is {width}x{height}",
                size.0.unwrap_or("?"),
                size.1.unwrap_or("?")
            )));
        }
        Ok(Self { width, height, window, provenance })
    }
}

#[cfg(all(test, feature = "image"))]
mod tests {
    use super::*;
    use crate::{BuildOptions, Material, SceneBuilder};

    fn scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::diffuse(Vec3::splat(0.5)));
        b.add_sphere(Vec3::ZERO, 1.0, m).unwrap();
        b.commit(&BuildOptions::default()).0
    }

    fn part(window: PixelBounds, seed: u64) -> ImagePart {
        let s = scene();
        let settings = RenderSettings { width: 40, height: 30, seed, ..RenderSettings::default() };
        let camera = s.camera_or_framing(40.0 / 30.0);
        let mut film = Film::new(window.width(), window.height());
        for (i, p) in film.pixels.iter_mut().enumerate() {
            *p = Vec3::new(i as f32, -0.5, f32::MIN_POSITIVE * i as f32);
        }
        let provenance = Provenance::new("sphere ä%.dae", &s, &camera, &settings, &[("bvh", "medium".into())]);
        ImagePart { width: 40, height: 30, window, film, provenance }
    }

    #[test]
    fn parts_round_trip_bit_for_bit_with_their_windows() {
        for window in [PixelBounds::full(40, 30), PixelBounds { x0: 3, x1: 17, y0: 29, y1: 30 }] {
            let p = part(window, 7);
            let bytes = p.encode_exr().unwrap();
            assert_eq!(bytes, p.encode_exr().unwrap(), "the same bytes every time");
            let back = ImagePart::decode_exr(&bytes).unwrap();
            assert_eq!(back.window, window);
            assert_eq!((back.width, back.height), (40, 30));
            assert_eq!(back.provenance, p.provenance);
            assert!(
                back.film
                    .pixels
                    .iter()
                    .zip(&p.film.pixels)
                    .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits))
            );
        }
        assert_eq!(part(PixelBounds::full(40, 30), 7).provenance.get("scene"), Some("sphere %C3%A4%25.dae"));
    }

    #[test]
    fn provenance_differences_name_the_fields() {
        let (a, b) = (part(PixelBounds::full(40, 30), 1).provenance, part(PixelBounds::full(40, 30), 2).provenance);
        assert_eq!(a.differences(&b), vec![("seed", Some("1"), Some("2"))]);
        assert!(a.differences(&a).is_empty());
        assert!(Provenance::from_text(&a.to_text()).unwrap() == a);
        assert!(Provenance::from_text("seed=1\n").is_err());
    }

    #[test]
    fn other_files_are_refused_without_panicking() {
        let full = part(PixelBounds::full(40, 30), 1);
        let plain = full.film.encode(super::super::ImageFormat::Exr, super::super::Encoding::Srgb).unwrap();
        let e = ImagePart::decode_exr(&plain).unwrap_err().to_string();
        assert!(e.contains("no `raypack` attribute"), "{e}");
        let bytes = full.encode_exr().unwrap();
        for cut in [0, 10, 100, bytes.len() / 2, bytes.len() - 1] {
            assert!(ImagePart::decode_exr(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        assert!(ImagePart::decode_exr(b"P6 not an exr").is_err());
    }
}
