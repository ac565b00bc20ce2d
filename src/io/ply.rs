// Not split: one format's header parser and its three body readers, with their unit tests.
//! PLY, the Stanford polygon file format (Greg Turk, 1994), as the Stanford 3D Scanning
//! Repository ships it: ASCII, `binary_little_endian` and `binary_big_endian` bodies.
//!
//! Read: the `vertex` element's `x y z` (any scalar type: `char`…`double` or their
//! `int8`…`float64` aliases; other vertex properties are skipped) and the `face` element's
//! `vertex_indices` (or `vertex_index`) list with any count and index type; polygons are
//! fan-triangulated, faces with fewer than three corners are skipped and counted. Every other
//! element and property is skipped.
//!
//! Fast and bounded: the body is parsed in one pass straight into the output arrays (no
//! per-vertex or per-face allocation, no quadratic step), and the header's element counts are
//! checked against the bytes that follow before anything is allocated, so a 1 kB file
//! claiming 4e9 vertices fails at once with an error instead of reserving gigabytes.
//!
//! (One file past 600 lines: the header parser and the readers of the three body encodings
//! share one property model and its bounds checks, so they read best together.)

use crate::io::LoadError;
use crate::math::Vec3;
use std::path::Path;

/// The header may not exceed this many bytes (real headers are a few hundred).
pub const MAX_HEADER_BYTES: usize = 64 * 1024;

/// A triangle mesh read from a PLY file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyMesh {
    /// Vertex positions, in file order.
    pub positions: Vec<Vec3>,
    /// Triangles (polygons fan-triangulated), all indices `< positions.len()`.
    pub triangles: Vec<[u32; 3]>,
    /// Faces with fewer than three corners, skipped.
    pub skipped_faces: usize,
}

/// Body encodings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyFormat {
    /// Whitespace-separated text.
    Ascii,
    /// Packed little-endian scalars.
    BinaryLittleEndian,
    /// Packed big-endian scalars.
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    line: usize,
}

impl Element {
    /// The fewest body bytes one instance can occupy: what the header's count is checked against.
    fn min_bytes(&self, format: PlyFormat) -> u64 {
        let n = match format {
            // Every value is at least one character plus one separator.
            PlyFormat::Ascii => 2 * self.props.len(),
            _ => self
                .props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(s) => s.size(),
                    Kind::List { count, .. } => count.size(),
                })
                .sum(),
        };
        n.max(1) as u64
    }
}

struct Header {
    format: PlyFormat,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body: usize,
    /// Bytes after the header.
    body_len: u64,
    /// Lines in the header (the body's first line is `lines + 1`).
    lines: usize,
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, LoadError> {
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err(LoadError::at_line(path, 1, "not a PLY file (it must start with the line \"ply\")"));
    }
    let window = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let end = find_end_header(window).ok_or_else(|| {
        let what = if bytes.len() > MAX_HEADER_BYTES {
            format!("no \"end_header\" line within the first {MAX_HEADER_BYTES} bytes")
        } else {
            "truncated header: no \"end_header\" line".to_string()
        };
        LoadError::at_line(path, window.split(|&b| b == b'\n').count(), what)
    })?;
    let text = std::str::from_utf8(&bytes[..end])
        .map_err(|e| LoadError::parse(path, format!("byte {}", e.valid_up_to()), "header is not ASCII text"))?;

    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut lines = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        lines = line_no;
        let mut w = raw.split_ascii_whitespace();
        let bad = |msg: String| LoadError::at_line(path, line_no, msg);
        match w.next() {
            None | Some("ply") if line_no == 1 => {}
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                let f = match w.next() {
                    Some("ascii") => PlyFormat::Ascii,
                    Some("binary_little_endian") => PlyFormat::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyFormat::BinaryBigEndian,
                    other => return Err(bad(format!("unknown format {:?}", other.unwrap_or("")))),
                };
                if w.next() != Some("1.0") {
                    return Err(bad("only PLY version 1.0 is supported".into()));
                }
                format = Some(f);
            }
            Some("element") => {
                let (Some(name), Some(count)) = (w.next(), w.next()) else {
                    return Err(bad("expected \"element NAME COUNT\"".into()));
                };
                let count: u64 =
                    count.parse().map_err(|_| bad(format!("element {name}: count {count:?} is not a whole number")))?;
                elements.push(Element { name: name.to_string(), count, props: Vec::new(), line: line_no });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("property before any element".into()));
                };
                let ty = w.next().unwrap_or("");
                let kind = if ty == "list" {
                    let (c, t) = (w.next().unwrap_or(""), w.next().unwrap_or(""));
                    let count = Scalar::from_name(c).ok_or_else(|| bad(format!("unknown list count type {c:?}")))?;
                    let item = Scalar::from_name(t).ok_or_else(|| bad(format!("unknown list item type {t:?}")))?;
                    if count.is_float() {
                        return Err(bad(format!("list count type {c} must be an integer type")));
                    }
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(Scalar::from_name(ty).ok_or_else(|| bad(format!("unknown property type {ty:?}")))?)
                };
                let name = w.next().ok_or_else(|| bad("property without a name".into()))?;
                el.props.push(Property { name: name.to_string(), kind });
            }
            Some("end_header") => break,
            Some(other) => return Err(bad(format!("unexpected header keyword {other:?}"))),
        }
    }
    let format = format.ok_or_else(|| LoadError::at_line(path, 2, "missing \"format\" line"))?;

    // The caps: every element's claimed count must fit in the bytes that follow.
    let body_len = (bytes.len() - end) as u64;
    for el in &elements {
        let need = el.count.saturating_mul(el.min_bytes(format));
        if need > body_len {
            return Err(LoadError::at_line(
                path,
                el.line,
                format!(
                    "header claims {} {} elements (at least {need} bytes) but only {body_len} bytes follow the header",
                    el.count, el.name
                ),
            ));
        }
    }
    Ok(Header { format, elements, body: end, body_len, lines })
}

/// Byte offset just past the `end_header` line.
fn find_end_header(window: &[u8]) -> Option<usize> {
    let mut start = 0;
    for (i, &b) in window.iter().enumerate() {
        if b == b'\n' {
            if window[start..i].trim_ascii() == b"end_header" {
                return Some(i + 1);
            }
            start = i + 1;
        }
    }
    None
}

/// Reads scalars from the body, ASCII or binary.
trait ValueReader {
    /// A value as `f32` (coordinates).
    fn real(&mut self, ty: Scalar) -> Result<f32, String>;
    /// A whole value (list counts and vertex indices).
    fn int(&mut self, ty: Scalar) -> Result<i64, String>;
    /// Skips one value.
    fn skip(&mut self, ty: Scalar) -> Result<(), String>;
    /// Where the reader is, for messages.
    fn location(&self) -> String;
}

struct AsciiReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> AsciiReader<'a> {
    #[inline]
    fn token(&mut self) -> Result<&'a [u8], String> {
        let b = self.bytes;
        let mut p = self.pos;
        while p < b.len() {
            let c = b[p];
            if c == b'\n' {
                self.line += 1;
            } else if !c.is_ascii_whitespace() {
                break;
            }
            p += 1;
        }
        if p >= b.len() {
            self.pos = p;
            return Err("unexpected end of file".into());
        }
        let start = p;
        while p < b.len() && !b[p].is_ascii_whitespace() {
            p += 1;
        }
        self.pos = p;
        Ok(&b[start..p])
    }
}

fn show(tok: &[u8]) -> String {
    format!("{:?}", String::from_utf8_lossy(&tok[..tok.len().min(40)]))
}

/// Parses a decimal integer without allocating.
#[inline]
fn parse_int(tok: &[u8]) -> Option<i64> {
    let (neg, digits) = match tok.first()? {
        b'-' => (true, &tok[1..]),
        b'+' => (false, &tok[1..]),
        _ => (false, tok),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (d - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

impl ValueReader for AsciiReader<'_> {
    #[inline]
    fn real(&mut self, _ty: Scalar) -> Result<f32, String> {
        let tok = self.token()?;
        std::str::from_utf8(tok)
            .ok()
            .and_then(|s| s.parse::<f32>().ok())
            .ok_or_else(|| format!("expected a number, found {}", show(tok)))
    }

    #[inline]
    fn int(&mut self, ty: Scalar) -> Result<i64, String> {
        let tok = self.token()?;
        if let Some(v) = parse_int(tok) {
            return Ok(v);
        }
        // A float-typed index list: accept whole values.
        let f = std::str::from_utf8(tok).ok().and_then(|s| s.parse::<f64>().ok());
        f.filter(|_| ty.is_float())
            .and_then(whole_number)
            .ok_or_else(|| format!("expected a whole number, found {}", show(tok)))
    }

    #[inline]
    fn skip(&mut self, _ty: Scalar) -> Result<(), String> {
        self.token().map(|_| ())
    }

    fn location(&self) -> String {
        format!("line {}", self.line)
    }
}

struct BinaryReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl BinaryReader<'_> {
    #[inline]
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let s = self.bytes.get(self.pos..self.pos + N).ok_or("unexpected end of file")?;
        self.pos += N;
        Ok(s.try_into().expect("slice of length N"))
    }

    #[inline]
    fn value(&mut self, ty: Scalar) -> Result<f64, String> {
        macro_rules! read {
            ($t:ty) => {{
                let b = self.take::<{ size_of::<$t>() }>()?;
                (if self.big_endian { <$t>::from_be_bytes(b) } else { <$t>::from_le_bytes(b) }) as f64
            }};
        }
        Ok(match ty {
            Scalar::I8 => read!(i8),
            Scalar::U8 => read!(u8),
            Scalar::I16 => read!(i16),
            Scalar::U16 => read!(u16),
            Scalar::I32 => read!(i32),
            Scalar::U32 => read!(u32),
            Scalar::F32 => read!(f32),
            Scalar::F64 => read!(f64),
        })
    }
}

/// `v` as an integer when it is a whole number below 1e15 in magnitude (an index or a list
/// length stored as a float), else `None`.
//
// Compared with its conversion rather than through `fract`, which on the x86-64 baseline
// (no SSE4.1) calls libm's `trunc` for every value read, indices included (PERFORMANCE.md,
// "Smaller measured choices").
#[inline]
fn whole_number(v: f64) -> Option<i64> {
    (v.abs() < 1e15 && (v as i64) as f64 == v).then_some(v as i64)
}

impl ValueReader for BinaryReader<'_> {
    #[inline]
    fn real(&mut self, ty: Scalar) -> Result<f32, String> {
        Ok(self.value(ty)? as f32)
    }

    #[inline]
    fn int(&mut self, ty: Scalar) -> Result<i64, String> {
        let v = self.value(ty)?;
        whole_number(v).ok_or_else(|| format!("expected a whole number, found {v:?}"))
    }

    #[inline]
    fn skip(&mut self, ty: Scalar) -> Result<(), String> {
        let n = ty.size();
        if self.pos + n > self.bytes.len() {
            return Err("unexpected end of file".into());
        }
        self.pos += n;
        Ok(())
    }

    fn location(&self) -> String {
        format!("byte {}", self.pos)
    }
}

/// Parses a PLY file held in memory. `path` only names the file in errors.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<PlyMesh, LoadError> {
    let header = parse_header(bytes, path)?;
    let body = &bytes[header.body..];
    match header.format {
        PlyFormat::Ascii => {
            let mut r = AsciiReader { bytes: body, pos: 0, line: header.lines + 1 };
            read_body(&mut r, &header, path)
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            let big_endian = header.format == PlyFormat::BinaryBigEndian;
            let mut r = BinaryReader { bytes: body, pos: 0, big_endian };
            read_body(&mut r, &header, path)
        }
    }
}

fn read_body<R: ValueReader>(r: &mut R, header: &Header, path: &Path) -> Result<PlyMesh, LoadError> {
    let mut mesh = PlyMesh::default();
    let mut have_vertices = false;
    // Triangles read before the vertex element (unusual order) are checked at the end.
    let mut unchecked_from = None;
    for el in &header.elements {
        let fail = |r: &R, what: String| LoadError::parse(path, r.location(), what);
        match el.name.as_str() {
            "vertex" if !have_vertices => {
                let find = |n: &str| el.props.iter().position(|p| p.name == n);
                let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
                    return Err(LoadError::at_line(path, el.line, "element vertex lacks an x, y or z property"));
                };
                if el.count > u32::MAX as u64 {
                    return Err(LoadError::at_line(path, el.line, format!("{} vertices exceed 2^32", el.count)));
                }
                mesh.positions.reserve_exact(el.count as usize);
                for v in 0..el.count {
                    let mut p = [0.0f32; 3];
                    for (k, prop) in el.props.iter().enumerate() {
                        let slot = if k == ix {
                            Some(0)
                        } else if k == iy {
                            Some(1)
                        } else if k == iz {
                            Some(2)
                        } else {
                            None
                        };
                        let res = match (prop.kind, slot) {
                            (Kind::Scalar(t), Some(s)) => r.real(t).map(|x| p[s] = x),
                            (Kind::Scalar(t), None) => r.skip(t),
                            (Kind::List { count, item }, _) => skip_list(r, count, item),
                        };
                        res.map_err(|e| fail(r, format!("vertex {v}: {e}")))?;
                    }
                    mesh.positions.push(Vec3::from_array(p));
                }
                have_vertices = true;
            }
            "face" => {
                let Some(il) = el.props.iter().position(|p| {
                    (p.name == "vertex_indices" || p.name == "vertex_index") && matches!(p.kind, Kind::List { .. })
                }) else {
                    return Err(LoadError::at_line(path, el.line, "element face has no vertex_indices list"));
                };
                if !have_vertices && unchecked_from.is_none() {
                    unchecked_from = Some(mesh.triangles.len());
                }
                let nv = if have_vertices { mesh.positions.len() as i64 } else { u32::MAX as i64 };
                // Reserve for one triangle per face, bounded by what the body could hold.
                let min_tri_bytes = match header.format {
                    PlyFormat::Ascii => 8,
                    _ => 4,
                };
                let cap = el.count.min(header.body_len / min_tri_bytes);
                mesh.triangles.reserve(cap as usize);
                for f in 0..el.count {
                    for (k, prop) in el.props.iter().enumerate() {
                        let res = match prop.kind {
                            Kind::List { count, item } if k == il => read_polygon(r, count, item, nv, &mut mesh),
                            Kind::List { count, item } => skip_list(r, count, item),
                            Kind::Scalar(t) => r.skip(t),
                        };
                        res.map_err(|e| fail(r, format!("face {f}: {e}")))?;
                    }
                }
            }
            _ => {
                for i in 0..el.count {
                    for prop in &el.props {
                        let res = match prop.kind {
                            Kind::List { count, item } => skip_list(r, count, item),
                            Kind::Scalar(t) => r.skip(t),
                        };
                        res.map_err(|e| fail(r, format!("{} {i}: {e}", el.name)))?;
                    }
                }
            }
        }
    }
    if let Some(from) = unchecked_from {
        let n = mesh.positions.len();
        for (t, tri) in mesh.triangles.iter().enumerate().skip(from) {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(LoadError::parse(
                    path,
                    format!("triangle {t}"),
                    format!("vertex index {i} out of range: the file has {n} vertices"),
                ));
            }
        }
    }
    Ok(mesh)
}

#[inline]
fn skip_list<R: ValueReader>(r: &mut R, count: Scalar, item: Scalar) -> Result<(), String> {
    let n = r.int(count)?;
    if n < 0 {
        return Err(format!("negative list length {n}"));
    }
    for _ in 0..n {
        r.skip(item)?;
    }
    Ok(())
}

/// Reads one polygon's index list and fan-triangulates it into `mesh.triangles`.
#[inline]
fn read_polygon<R: ValueReader>(
    r: &mut R,
    count: Scalar,
    item: Scalar,
    num_vertices: i64,
    mesh: &mut PlyMesh,
) -> Result<(), String> {
    let n = r.int(count)?;
    if n < 0 {
        return Err(format!("negative list length {n}"));
    }
    let index = |r: &mut R| -> Result<u32, String> {
        let i = r.int(item)?;
        if i < 0 || i >= num_vertices {
            return Err(format!("vertex index {i} out of range: the file has {num_vertices} vertices"));
        }
        Ok(i as u32)
    };
    if n < 3 {
        for _ in 0..n {
            index(r)?;
        }
        mesh.skipped_faces += 1;
        return Ok(());
    }
    let v0 = index(r)?;
    let mut v1 = index(r)?;
    for _ in 2..n {
        let v2 = index(r)?;
        mesh.triangles.push([v0, v1, v2]);
        v1 = v2;
    }
    Ok(())
}

/// Writes `mesh` as PLY in the given format (for tests, tools and fuzz corpora).
pub fn write_ply(positions: &[Vec3], triangles: &[[u32; 3]], format: PlyFormat) -> Vec<u8> {
    let name = match format {
        PlyFormat::Ascii => "ascii",
        PlyFormat::BinaryLittleEndian => "binary_little_endian",
        PlyFormat::BinaryBigEndian => "binary_big_endian",
    };
    let mut out = format!(
        "ply\nformat {name} 1.0\ncomment written by raypack\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        positions.len(),
        triangles.len()
    )
    .into_bytes();
    match format {
        PlyFormat::Ascii => {
            use std::io::Write;
            for p in positions {
                writeln!(out, "{} {} {}", p.x, p.y, p.z).expect("write to Vec");
            }
            for t in triangles {
                writeln!(out, "3 {} {} {}", t[0], t[1], t[2]).expect("write to Vec");
            }
        }
        _ => {
            let be = format == PlyFormat::BinaryBigEndian;
            for p in positions {
                for c in p.to_array() {
                    out.extend_from_slice(&if be { c.to_be_bytes() } else { c.to_le_bytes() });
                }
            }
            for t in triangles {
                out.push(3);
                for &i in t {
                    let i = i as i32;
                    out.extend_from_slice(&if be { i.to_be_bytes() } else { i.to_le_bytes() });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.ply")
    }

    #[test]
    fn reads_quads_and_skips_extra_properties_and_elements() {
        let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty float confidence\n\
                    property float y\nproperty short z\nelement face 1\nproperty uchar flags\n\
                    property list uint short vertex_index\nelement edge 1\nproperty int a\nproperty int b\nend_header\n\
                    0 1 0 0\n1 1 0 0\n1 1 1 0\n0 1 1 7\n9 4 0 1 2 3\n0 1\n";
        let m = parse_ply(text.as_bytes(), p()).unwrap();
        assert_eq!(m.positions[3], Vec3::new(0.0, 1.0, 7.0));
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn huge_claimed_count_fails_before_allocating() {
        let text = "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0";
        let e = parse_ply(text.as_bytes(), p()).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("4000000000 vertex"), "{e}");
    }

    #[test]
    fn reports_line_of_bad_token_and_out_of_range_index() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 x 0\n3 0 1 2\n";
        let e = parse_ply(text.as_bytes(), p()).unwrap_err().to_string();
        assert!(e.contains("line 12") && e.contains("vertex 2"), "{e}");
        let text = text.replace("0 x 0", "0 1 0").replace("3 0 1 2", "3 0 1 3");
        let e = parse_ply(text.as_bytes(), p()).unwrap_err().to_string();
        assert!(e.contains("line 13") && e.contains("index 3 out of range"), "{e}");
    }

    #[test]
    fn float_typed_index_lists_take_whole_values_only() {
        let header = |format: &str| {
            format!(
                "ply\nformat {format} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 1\nproperty list uchar double vertex_indices\nend_header\n"
            )
        };
        let binary = |last: f64| {
            let mut b = header("binary_little_endian").into_bytes();
            for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.push(3);
            for i in [0.0, 1.0, last] {
                b.extend_from_slice(&f64::to_le_bytes(i));
            }
            b
        };
        assert_eq!(parse_ply(&binary(2.0), p()).unwrap().triangles, vec![[0, 1, 2]]);
        // -0.0 is whole (vertex 0); the rest are not, or out of the range of indices.
        assert_eq!(parse_ply(&binary(-0.0), p()).unwrap().triangles, vec![[0, 1, 0]]);
        for (last, shown) in [(1.5, "1.5"), (-0.25, "-0.25"), (f64::NAN, "NaN"), (1e300, "1e300")] {
            let e = parse_ply(&binary(last), p()).unwrap_err().to_string();
            assert!(e.contains(&format!("expected a whole number, found {shown}")), "{e}");
        }
        let ascii = |last: &str| format!("{}0 0 0\n1 0 0\n0 1 0\n3 0 1.0 {last}\n", header("ascii"));
        assert_eq!(parse_ply(ascii("2").as_bytes(), p()).unwrap().triangles, vec![[0, 1, 2]]);
        assert_eq!(parse_ply(ascii("2.0").as_bytes(), p()).unwrap().triangles, vec![[0, 1, 2]]);
        let e = parse_ply(ascii("2.5").as_bytes(), p()).unwrap_err().to_string();
        assert!(e.contains("line 13") && e.contains("expected a whole number, found \"2.5\""), "{e}");
    }
}
