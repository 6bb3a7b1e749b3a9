//! A still picture of a scene: particles (circles, optionally coloured by a scalar), line
//! segments and triangle meshes (flat shaded under one light, or wireframe), seen by a fixed
//! camera and drawn back to front into an SVG.
//!
//! The SVG is written here rather than through plotters: a frame is thousands of small
//! shapes, and writing them directly lets every shape of a kind share one group's style
//! (stroke, widths), with coordinates to a tenth of a pixel, which keeps the files small
//! enough to go into a repository (a few hundred bytes of header, then about 60 bytes a
//! particle and 70 a triangle).

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;

use crate::PlotError;

/// A colour, red, green and blue.
pub type Rgb = [u8; 3];

/// A point or direction as the API takes it (plain arrays: no maths library in the signatures);
/// the drawing converts to glam's `DVec3`.
type V3 = [f64; 3];

/// `a` over its length, or None for a zero or non-finite vector. Divides by the length rather
/// than multiplying by its reciprocal (glam's `try_normalize`), which rounds differently and
/// would move shapes by a tenth of a pixel now and then.
fn normalize(a: DVec3) -> Option<DVec3> {
    let n = a.length();
    (n > 0.0 && n.is_finite()).then(|| a / n)
}

/// How the camera maps depth: parallel rays, or rays through the eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    Orthographic,
    Perspective,
}

/// A camera at `eye` looking at `target`, with `up` pointing up in the picture. The picture
/// is always zoomed and centred to hold everything drawn (so neither a field of view nor a
/// scale is needed): the eye's position sets the viewing direction and, in perspective, how
/// strong the foreshortening is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: V3,
    pub target: V3,
    pub up: V3,
    pub projection: Projection,
}

impl Camera {
    /// A perspective camera.
    pub fn perspective(eye: V3, target: V3, up: V3) -> Camera {
        Camera {
            eye,
            target,
            up,
            projection: Projection::Perspective,
        }
    }

    /// An orthographic camera (only the direction from `eye` to `target` matters).
    pub fn orthographic(eye: V3, target: V3, up: V3) -> Camera {
        Camera {
            eye,
            target,
            up,
            projection: Projection::Orthographic,
        }
    }

    /// The camera's frame: right, up and forward unit vectors, or why there is none.
    fn basis(&self) -> Result<[DVec3; 3], PlotError> {
        let bad = || {
            PlotError::new(format!(
                "camera: eye {:?}, target {:?} and up {:?} do not give a view (eye at the \
                 target, or up along the view)",
                self.eye, self.target, self.up
            ))
        };
        let f = normalize(DVec3::from(self.target) - DVec3::from(self.eye)).ok_or_else(bad)?;
        let r = normalize(f.cross(DVec3::from(self.up))).ok_or_else(bad)?;
        Ok([r, r.cross(f), f])
    }
}

/// Particles: a circle of world-space `radius` at each position.
#[derive(Clone, Debug)]
pub struct Points {
    positions: Vec<V3>,
    radius: f64,
    colour: Rgb,
    values: Option<(String, Vec<f64>)>,
}

impl Points {
    /// Particles of `radius` (world units; at least 0.6 pixel is drawn), coloured blue.
    pub fn new(positions: impl IntoIterator<Item = V3>, radius: f64) -> Points {
        Points {
            positions: positions.into_iter().collect(),
            radius,
            colour: [52, 101, 164],
            values: None,
        }
    }

    /// One colour for every particle.
    pub fn colour(mut self, colour: Rgb) -> Points {
        self.colour = colour;
        self
    }

    /// Colours each particle by its value (one per position, in order) on a viridis-like
    /// scale from the smallest to the largest, shown in a legend named `label`.
    pub fn values(mut self, label: &str, values: impl IntoIterator<Item = f64>) -> Points {
        self.values = Some((label.to_string(), values.into_iter().collect()));
        self
    }

    /// The particles' positions.
    pub fn positions(&self) -> &[V3] {
        &self.positions
    }

    /// The particles' radius, in world units.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// The set's one colour (the particles' colour when no values colour them).
    pub fn rgb(&self) -> Rgb {
        self.colour
    }

    /// The scalar that colours the particles, with its label, if one does.
    pub fn scalar(&self) -> Option<(&str, &[f64])> {
        self.values
            .as_ref()
            .map(|(l, v)| (l.as_str(), v.as_slice()))
    }

    /// The smallest and largest finite value of the colouring scalar ((0, 0) if none is
    /// finite), or None without one.
    pub fn value_range(&self) -> Option<(f64, f64)> {
        let (_, v) = self.values.as_ref()?;
        let (lo, hi) = v
            .iter()
            .filter(|x| x.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
        Some(if lo <= hi { (lo, hi) } else { (0.0, 0.0) })
    }

    /// The colour particle `i` is drawn in: its value on the colour scale between the set's
    /// smallest and largest value (`range`, from `value_range`), else the set's colour.
    pub fn colour_of(&self, i: usize, range: Option<(f64, f64)>) -> Rgb {
        match (&self.values, range) {
            (Some((_, v)), Some((lo, hi))) => scale_colour(if hi > lo {
                (v.get(i).copied().unwrap_or(lo) - lo) / (hi - lo)
            } else {
                0.5
            }),
            _ => self.colour,
        }
    }
}

/// How a triangle mesh is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeshStyle {
    /// Flat shaded faces under one light from the upper left of the camera (both sides lit).
    Shaded,
    /// Every edge once, as a line.
    Wireframe,
}

/// A triangle mesh: points and triangles indexing them.
#[derive(Clone, Debug)]
pub struct TriMesh {
    points: Vec<V3>,
    triangles: Vec<[usize; 3]>,
    style: MeshStyle,
    colour: Rgb,
    closed: bool,
}

impl TriMesh {
    /// A shaded, light grey mesh.
    pub fn new(points: impl IntoIterator<Item = V3>, triangles: Vec<[usize; 3]>) -> TriMesh {
        TriMesh {
            points: points.into_iter().collect(),
            triangles,
            style: MeshStyle::Shaded,
            colour: [200, 200, 196],
            closed: false,
        }
    }

    /// Draws the edges instead of the faces.
    pub fn wireframe(mut self) -> TriMesh {
        self.style = MeshStyle::Wireframe;
        self
    }

    pub fn colour(mut self, colour: Rgb) -> TriMesh {
        self.colour = colour;
        self
    }

    /// The mesh is closed (a watertight surface): faces turned away from the camera are
    /// hidden behind others and are not drawn, which halves the file. Which side is outside
    /// comes from the sign of the enclosed volume, so either winding works.
    pub fn closed(mut self) -> TriMesh {
        self.closed = true;
        self
    }

    /// The mesh's points.
    pub fn points(&self) -> &[V3] {
        &self.points
    }

    /// The triangles, as indices into `points`.
    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }

    /// Shaded faces or wireframe.
    pub fn style(&self) -> MeshStyle {
        self.style
    }

    /// The mesh's colour.
    pub fn rgb(&self) -> Rgb {
        self.colour
    }

    /// Whether the mesh was marked closed (watertight).
    pub fn is_closed(&self) -> bool {
        self.closed
    }
}

/// Line segments of one colour (springs, chains, a box's edges).
#[derive(Clone, Debug)]
pub struct Lines {
    segments: Vec<[V3; 2]>,
    colour: Rgb,
    width: f64,
}

impl Lines {
    /// Segments, dark grey, 1.2 pixels wide.
    pub fn new(segments: impl IntoIterator<Item = [V3; 2]>) -> Lines {
        Lines {
            segments: segments.into_iter().collect(),
            colour: [60, 60, 60],
            width: 1.2,
        }
    }

    /// The segments joining consecutive points.
    pub fn polyline(points: &[V3]) -> Lines {
        Lines::new(points.windows(2).map(|w| [w[0], w[1]]))
    }

    /// The twelve edges of the box `lo`..`hi`.
    pub fn bounding_box(lo: V3, hi: V3) -> Lines {
        let corner = |k: usize| {
            [
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            ]
        };
        let edges = (0..8usize).flat_map(|a| {
            [1usize, 2, 4]
                .into_iter()
                .filter(move |&bit| a & bit == 0)
                .map(move |bit| [corner(a), corner(a | bit)])
        });
        Lines::new(edges).colour([150, 150, 150]).width(0.8)
    }

    pub fn colour(mut self, colour: Rgb) -> Lines {
        self.colour = colour;
        self
    }

    /// The width in pixels.
    pub fn width(mut self, width: f64) -> Lines {
        self.width = width;
        self
    }

    /// The segments, each a pair of end points.
    pub fn segments(&self) -> &[[V3; 2]] {
        &self.segments
    }

    /// The lines' colour.
    pub fn rgb(&self) -> Rgb {
        self.colour
    }

    /// The lines' width in pixels.
    pub fn pixel_width(&self) -> f64 {
        self.width
    }
}

/// One picture: a title, notes under it, and what is drawn, seen by a camera.
///
/// ```
/// use warp_report::frame::{Camera, Frame, Points, TriMesh};
/// let ground = TriMesh::new(
///     [[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]],
///     vec![[0, 1, 2], [0, 2, 3]],
/// );
/// let balls = Points::new((0..10).map(|i| [i as f64 * 0.2 - 1.0, 0.1, 0.0]), 0.1)
///     .values("height (m)", (0..10).map(|i| i as f64));
/// let svg = Frame::new("ten balls", Camera::perspective([0.0, 2.0, 4.0], [0.0; 3], [0.0, 1.0, 0.0]))
///     .mesh(ground)
///     .points(balls)
///     .to_svg()
///     .unwrap();
/// assert_eq!(svg.matches("<circle").count(), 10);
/// ```
#[derive(Clone, Debug)]
pub struct Frame {
    title: String,
    notes: Vec<String>,
    camera: Camera,
    size: (u32, u32),
    max_points: usize,
    points: Vec<Points>,
    meshes: Vec<TriMesh>,
    lines: Vec<Lines>,
}

/// A shape ready to draw, in pixels, with its depth (larger is farther).
enum Shape {
    Circle {
        c: [f64; 2],
        r: f64,
        colour: Rgb,
    },
    Triangle {
        p: [[f64; 2]; 3],
        colour: Rgb,
    },
    Segment {
        p: [[f64; 2]; 2],
        colour: Rgb,
        width: f64,
    },
}

/// The viridis-like colour scale at t in [0, 1] (dark blue, teal, green, yellow).
pub fn scale_colour(t: f64) -> Rgb {
    const STOPS: [Rgb; 6] = [
        [68, 1, 84],
        [65, 68, 135],
        [42, 120, 142],
        [34, 168, 132],
        [122, 209, 81],
        [253, 231, 37],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STOPS.len() - 1) as f64;
    let k = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - k as f64;
    let mix =
        |c: usize| (STOPS[k][c] as f64 * (1.0 - f) + STOPS[k + 1][c] as f64 * f).round() as u8;
    [mix(0), mix(1), mix(2)]
}

fn shade(c: Rgb, k: f64) -> Rgb {
    c.map(|v| (v as f64 * k).round().clamp(0.0, 255.0) as u8)
}

fn hex(c: Rgb) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// Text for an SVG text node.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A number to at most one decimal, without a trailing ".0".
fn num(v: f64) -> String {
    let r = (v * 10.0).round() / 10.0;
    if r == r.trunc() {
        format!("{}", r as i64)
    } else {
        format!("{r:.1}")
    }
}

/// A short form of a legend's bound.
fn label(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e4 || v.abs() < 1e-2) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

impl Frame {
    /// An empty 800 x 600 frame.
    pub fn new(title: impl Into<String>, camera: Camera) -> Frame {
        Frame {
            title: title.into(),
            notes: Vec::new(),
            camera,
            size: (800, 600),
            max_points: 3000,
            points: Vec::new(),
            meshes: Vec::new(),
            lines: Vec::new(),
        }
    }

    /// The picture's size in pixels.
    pub fn size(mut self, width: u32, height: u32) -> Frame {
        self.size = (width.max(64), height.max(64));
        self
    }

    /// A line of text under the title.
    pub fn note(mut self, text: impl Into<String>) -> Frame {
        self.notes.push(text.into());
        self
    }

    /// At most this many particles are drawn (default 3000): above it, one in k of each set
    /// is, and a note says so. It bounds the file's size.
    pub fn max_points(mut self, n: usize) -> Frame {
        self.max_points = n.max(1);
        self
    }

    pub fn points(mut self, points: Points) -> Frame {
        self.points.push(points);
        self
    }

    pub fn mesh(mut self, mesh: TriMesh) -> Frame {
        self.meshes.push(mesh);
        self
    }

    pub fn lines(mut self, lines: Lines) -> Frame {
        self.lines.push(lines);
        self
    }

    /// The title.
    pub fn title(&self) -> &str {
        &self.title
    }

    /// The lines of text under the title.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The particle sets, in the order they were added.
    pub fn point_sets(&self) -> &[Points] {
        &self.points
    }

    /// The triangle meshes, in the order they were added.
    pub fn meshes(&self) -> &[TriMesh] {
        &self.meshes
    }

    /// The line sets, in the order they were added.
    pub fn line_sets(&self) -> &[Lines] {
        &self.lines
    }

    /// Writes the SVG to `path`.
    pub fn write_svg(&self, path: &Path) -> Result<(), PlotError> {
        let svg = self.to_svg()?;
        std::fs::write(path, svg)
            .map_err(|e| PlotError::caused_by(crate::plot::cannot_write(path), e))
    }

    /// The SVG text: an error names what cannot be drawn (a degenerate camera, values that do
    /// not match the positions, a triangle index out of range).
    pub fn to_svg(&self) -> Result<String, PlotError> {
        let [right, up, forward] = self.camera.basis()?;
        let eye = DVec3::from(self.camera.eye);
        let perspective = self.camera.projection == Projection::Perspective;
        // Camera coordinates: (x, y) on the picture plane (perspective: divided by depth), z
        // the depth; None behind the eye.
        let view = |p: V3| -> Option<[f64; 3]> {
            let d = DVec3::from(p) - eye;
            let (x, y, z) = (d.dot(right), d.dot(up), d.dot(forward));
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                return None;
            }
            if perspective {
                (z > 1e-9).then(|| [x / z, y / z, z])
            } else {
                Some([x, y, z])
            }
        };

        // 1. Which particles are drawn.
        let total: usize = self.points.iter().map(|p| p.positions.len()).sum();
        let stride = total.div_ceil(self.max_points).max(1);
        for (k, set) in self.points.iter().enumerate() {
            if let Some((label, values)) = &set.values {
                if values.len() != set.positions.len() {
                    return Err(PlotError::new(format!(
                        "points {k}: {} values of \"{label}\" for {} positions",
                        values.len(),
                        set.positions.len()
                    )));
                }
            }
        }
        for (k, mesh) in self.meshes.iter().enumerate() {
            if let Some(t) = mesh
                .triangles
                .iter()
                .find(|t| t.iter().any(|&i| i >= mesh.points.len()))
            {
                return Err(PlotError::new(format!(
                    "mesh {k}: triangle {t:?} indexes past its {} points",
                    mesh.points.len()
                )));
            }
        }

        // 2. Everything in camera coordinates, with its world-space size where it has one.
        enum Item {
            Circle {
                c: [f64; 3],
                r: f64,
                colour: Rgb,
            },
            Triangle {
                p: [[f64; 3]; 3],
                colour: Rgb,
                light: f64,
            },
            Segment {
                p: [[f64; 3]; 2],
                colour: Rgb,
                width: f64,
            },
        }
        let mut items: Vec<Item> = Vec::new();
        let mut legends: Vec<(String, f64, f64)> = Vec::new();
        for set in &self.points {
            let range = set.value_range();
            if let (Some((label, _)), Some((lo, hi))) = (set.scalar(), range) {
                legends.push((label.to_string(), lo, hi));
            }
            for (i, &p) in set.positions.iter().enumerate().step_by(stride) {
                let Some(c) = view(p) else { continue };
                let colour = set.colour_of(i, range);
                items.push(Item::Circle {
                    c,
                    r: set.radius,
                    colour,
                });
            }
        }
        // The light, in world space: from the upper left of the camera, towards the scene.
        let light = normalize(right * -0.45 + up * 0.65 - forward * 0.6).unwrap_or(up);
        for mesh in &self.meshes {
            // A closed mesh's outward side: the sign of its enclosed volume.
            let volume: f64 = mesh
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| DVec3::from(mesh.points[i]));
                    a.dot(b.cross(c))
                })
                .sum();
            let outward = if volume < 0.0 { -1.0 } else { 1.0 };
            match mesh.style {
                MeshStyle::Shaded => {
                    for t in &mesh.triangles {
                        let [pa, pb, pc] = t.map(|i| mesh.points[i]);
                        let [a, b, c] = [pa, pb, pc].map(DVec3::from);
                        let Some(n) = normalize((b - a).cross(c - a)) else {
                            continue; // degenerate: no area to draw
                        };
                        if mesh.closed {
                            // Turned away: the ray from the eye to the face meets its back.
                            let to_face = if perspective { a - eye } else { forward };
                            if outward * n.dot(to_face) > 0.0 {
                                continue;
                            }
                        }
                        let (Some(qa), Some(qb), Some(qc)) = (view(pa), view(pb), view(pc)) else {
                            continue;
                        };
                        items.push(Item::Triangle {
                            p: [qa, qb, qc],
                            colour: mesh.colour,
                            light: n.dot(light).abs(),
                        });
                    }
                }
                MeshStyle::Wireframe => {
                    let mut seen = HashSet::new();
                    for t in &mesh.triangles {
                        for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                            if !seen.insert((i.min(j), i.max(j))) {
                                continue;
                            }
                            if let (Some(p), Some(q)) = (view(mesh.points[i]), view(mesh.points[j]))
                            {
                                items.push(Item::Segment {
                                    p: [p, q],
                                    colour: mesh.colour,
                                    width: 0.7,
                                });
                            }
                        }
                    }
                }
            }
        }
        for lines in &self.lines {
            for s in &lines.segments {
                if let (Some(p), Some(q)) = (view(s[0]), view(s[1])) {
                    items.push(Item::Segment {
                        p: [p, q],
                        colour: lines.colour,
                        width: lines.width,
                    });
                }
            }
        }

        // 3. The zoom: the picture-plane box of everything (circles with their radius at the
        // mean depth) into the drawing area, with a margin, keeping the aspect.
        let (w, h) = (self.size.0 as f64, self.size.1 as f64);
        let top = 34.0 + 18.0 * self.notes.len() as f64;
        let legend_w = if legends.is_empty() { 0.0 } else { 90.0 };
        let (area_w, area_h) = (w - 24.0 - legend_w, h - top - 12.0);
        // A 3% margin inside the area: nothing touches its edges.
        let (area_w, area_h) = (area_w * 0.94, area_h * 0.94);
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut zlo = f64::INFINITY;
        let mut zhi = f64::NEG_INFINITY;
        let mut grow = |q: [f64; 3]| {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
            zlo = zlo.min(q[2]);
            zhi = zhi.max(q[2]);
        };
        for item in &items {
            match item {
                Item::Circle { c, .. } => grow(*c),
                Item::Triangle { p, .. } => p.iter().for_each(|&q| grow(q)),
                Item::Segment { p, .. } => p.iter().for_each(|&q| grow(q)),
            }
        }
        let span = |k: usize| if hi[k] > lo[k] { hi[k] - lo[k] } else { 1.0 };
        let scale = if items.is_empty() {
            1.0
        } else {
            (area_w / span(0)).min(area_h / span(1))
        };
        let centre = [
            if lo[0] <= hi[0] {
                (lo[0] + hi[0]) / 2.0
            } else {
                0.0
            },
            if lo[1] <= hi[1] {
                (lo[1] + hi[1]) / 2.0
            } else {
                0.0
            },
        ];
        let (ox, oy) = (12.0 + area_w / 2.0, top + area_h / 2.0);
        let px = |q: [f64; 3]| {
            [
                ox + (q[0] - centre[0]) * scale,
                oy - (q[1] - centre[1]) * scale,
            ]
        };
        // Depth cue: the farthest shapes are drawn up to 30% darker.
        let zspan = if zhi > zlo { zhi - zlo } else { 1.0 };
        let cue = |z: f64| 1.0 - 0.3 * ((z - zlo) / zspan).clamp(0.0, 1.0);

        // 4. Shapes in pixels, farthest first (the painter's algorithm).
        let mut shapes: Vec<(f64, Shape)> = items
            .iter()
            .map(|item| match *item {
                Item::Circle { c, r, colour } => {
                    let r_px = if perspective { r / c[2] } else { r } * scale;
                    (
                        c[2],
                        Shape::Circle {
                            c: px(c),
                            r: r_px.max(0.6),
                            colour: shade(colour, cue(c[2])),
                        },
                    )
                }
                Item::Triangle { p, colour, light } => {
                    let z = (p[0][2] + p[1][2] + p[2][2]) / 3.0;
                    (
                        z,
                        Shape::Triangle {
                            p: p.map(px),
                            colour: shade(colour, (0.35 + 0.65 * light) * cue(z)),
                        },
                    )
                }
                Item::Segment { p, colour, width } => {
                    let z = (p[0][2] + p[1][2]) / 2.0;
                    (
                        z,
                        Shape::Segment {
                            p: p.map(px),
                            colour: shade(colour, cue(z)),
                            width,
                        },
                    )
                }
            })
            .collect();
        shapes.sort_by(|a, b| b.0.total_cmp(&a.0));

        // 5. The SVG: runs of one kind share a group's style.
        let mut svg = String::with_capacity(200 + shapes.len() * 64);
        let _ = writeln!(
            svg,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" viewBox=\"0 0 {} {}\" \
             font-family=\"sans-serif\">",
            self.size.0, self.size.1, self.size.0, self.size.1
        );
        let _ = writeln!(
            svg,
            "<rect width=\"100%\" height=\"100%\" fill=\"#fbfbf8\"/>"
        );
        let _ = writeln!(
            svg,
            "<text x=\"12\" y=\"24\" font-size=\"17\">{}</text>",
            escape(&self.title)
        );
        let mut notes = self.notes.clone();
        if stride > 1 {
            notes.push(format!("1 in {stride} of {total} particles drawn"));
        }
        for (k, n) in notes.iter().enumerate() {
            let _ = writeln!(
                svg,
                "<text x=\"12\" y=\"{}\" font-size=\"13\" fill=\"#555\">{}</text>",
                44 + 18 * k,
                escape(n)
            );
        }
        let mut group: Option<u8> = None;
        for (_, shape) in &shapes {
            let kind = match shape {
                Shape::Circle { .. } => 0,
                Shape::Triangle { .. } => 1,
                Shape::Segment { .. } => 2,
            };
            if group != Some(kind) {
                if group.is_some() {
                    svg.push_str("</g>\n");
                }
                svg.push_str(match kind {
                    // A thin dark rim tells touching particles apart.
                    0 => "<g stroke=\"#000\" stroke-opacity=\"0.35\" stroke-width=\"0.5\">\n",
                    // Each face stroked in its own colour: no hairline gaps between faces.
                    1 => "<g stroke-width=\"0.6\" stroke-linejoin=\"round\">\n",
                    _ => "<g fill=\"none\" stroke-linecap=\"round\">\n",
                });
                group = Some(kind);
            }
            match shape {
                Shape::Circle { c, r, colour } => {
                    let _ = writeln!(
                        svg,
                        "<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{}\"/>",
                        num(c[0]),
                        num(c[1]),
                        num(*r),
                        hex(*colour)
                    );
                }
                Shape::Triangle { p, colour } => {
                    let c = hex(*colour);
                    let _ = writeln!(
                        svg,
                        "<polygon points=\"{},{} {},{} {},{}\" fill=\"{c}\" stroke=\"{c}\"/>",
                        num(p[0][0]),
                        num(p[0][1]),
                        num(p[1][0]),
                        num(p[1][1]),
                        num(p[2][0]),
                        num(p[2][1])
                    );
                }
                Shape::Segment { p, colour, width } => {
                    let _ = writeln!(
                        svg,
                        "<path d=\"M{} {}L{} {}\" stroke=\"{}\" stroke-width=\"{}\"/>",
                        num(p[0][0]),
                        num(p[0][1]),
                        num(p[1][0]),
                        num(p[1][1]),
                        hex(*colour),
                        num(*width)
                    );
                }
            }
        }
        if group.is_some() {
            svg.push_str("</g>\n");
        }

        // 6. A colour bar per coloured set, at the right.
        for (k, (label_text, lo, hi)) in legends.iter().enumerate() {
            let x = w - legend_w + 8.0;
            let (y0, bar_h) = (top + 20.0 + k as f64 * 200.0, 140.0);
            let _ = writeln!(
                svg,
                "<text x=\"{}\" y=\"{}\" font-size=\"12\">{}</text>",
                num(x),
                num(y0 - 8.0),
                escape(label_text)
            );
            const BANDS: usize = 16;
            for b in 0..BANDS {
                let t = 1.0 - (b as f64 + 0.5) / BANDS as f64;
                let _ = writeln!(
                    svg,
                    "<rect x=\"{}\" y=\"{}\" width=\"14\" height=\"{}\" fill=\"{}\"/>",
                    num(x),
                    num(y0 + b as f64 * bar_h / BANDS as f64),
                    num(bar_h / BANDS as f64 + 0.5),
                    hex(scale_colour(t))
                );
            }
            for (y, v) in [(y0 + 10.0, hi), (y0 + bar_h, lo)] {
                let _ = writeln!(
                    svg,
                    "<text x=\"{}\" y=\"{}\" font-size=\"11\">{}</text>",
                    num(x + 18.0),
                    num(y),
                    label(*v)
                );
            }
        }
        svg.push_str("</svg>\n");
        Ok(svg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small frame of every kind of shape (coloured particles, a closed shaded mesh, a
    /// wireframe, lines) under an oblique perspective camera, for `the_pinned_frame_is_unchanged`.
    fn pinned_frame() -> Frame {
        let tet = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let faces = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        Frame::new(
            "pinned",
            Camera::perspective([3.1, 1.7, 2.3], [0.2, 0.3, 0.1], [0.1, 0.0, 1.0]),
        )
        .size(320, 240)
        .note("a note")
        .points(
            Points::new([[0.5, 0.5, 1.2], [-0.3, 0.2, 0.1], [1.1, -0.4, 0.6]], 0.07)
                .values("speed", [0.0, 0.5, 2.0]),
        )
        .mesh(TriMesh::new(tet.clone(), faces.clone()).closed())
        .mesh(
            TriMesh::new(tet.iter().map(|p| [p[0] - 1.5, p[1], p[2]]), faces)
                .wireframe()
                .colour([200, 30, 30]),
        )
        .lines(Lines::bounding_box([-1.6, -0.5, 0.0], [1.2, 1.1, 1.3]).width(1.5))
    }

    /// The SVG of `pinned_frame`, byte for byte as it was before the vector maths moved to glam
    /// (`WARP_REPORT_BLESS=1` rewrites the file after an intended change of the picture).
    #[test]
    fn the_pinned_frame_is_unchanged() {
        let svg = pinned_frame().to_svg().unwrap();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/testdata/pinned_frame.svg");
        if std::env::var_os("WARP_REPORT_BLESS").is_some() {
            std::fs::write(path, &svg).unwrap();
        }
        assert_eq!(svg, include_str!("testdata/pinned_frame.svg"));
    }

    fn cam() -> Camera {
        Camera::orthographic([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0])
    }

    /// The (cx, cy) of every circle, in order.
    fn circles(svg: &str) -> Vec<(f64, f64)> {
        svg.lines()
            .filter(|l| l.starts_with("<circle"))
            .map(|l| {
                let attr = |name: &str| -> f64 {
                    let s = &l[l.find(&format!("{name}=\"")).unwrap() + name.len() + 2..];
                    s[..s.find('"').unwrap()].parse().unwrap()
                };
                (attr("cx"), attr("cy"))
            })
            .collect()
    }

    #[test]
    fn points_are_placed_by_the_camera_and_drawn_back_to_front() {
        // Looking down -z with y up: +x is right, +y is up (smaller pixel y); the point at
        // z = -1 is farther, so it comes first.
        let svg = Frame::new("t", cam())
            .points(Points::new(
                [[1.0, 0.0, 0.0], [-1.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
                0.05,
            ))
            .to_svg()
            .unwrap();
        let c = circles(&svg);
        assert_eq!(c.len(), 3);
        let (near_right, far_left, up) = (c[1], c[0], c[2]);
        assert!(far_left.0 < near_right.0, "{c:?}");
        assert!(up.1 < near_right.1, "{c:?}");
    }

    #[test]
    fn perspective_shrinks_distant_particles() {
        let svg = Frame::new(
            "t",
            Camera::perspective([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0]),
        )
        .points(Points::new([[-1.0, 0.0, 2.0], [1.0, 0.0, -10.0]], 0.1))
        .to_svg()
        .unwrap();
        let radii: Vec<f64> = svg
            .lines()
            .filter(|l| l.starts_with("<circle"))
            .map(|l| {
                let s = &l[l.find("r=\"").unwrap() + 3..];
                s[..s.find('"').unwrap()].parse().unwrap()
            })
            .collect();
        // Depths 15 and 3: the far one is drawn first and five times smaller (to rounding).
        assert!((radii[1] / radii[0] - 5.0).abs() < 0.3, "{radii:?}");
    }

    #[test]
    fn subsampling_bounds_the_particles_and_says_so() {
        let svg = Frame::new("t", cam())
            .max_points(100)
            .points(Points::new((0..1000).map(|i| [i as f64, 0.0, 0.0]), 0.1))
            .to_svg()
            .unwrap();
        assert_eq!(svg.matches("<circle").count(), 100);
        assert!(svg.contains("1 in 10 of 1000 particles drawn"));
    }

    #[test]
    fn a_closed_mesh_hides_its_back_faces_whatever_its_winding() {
        // A tetrahedron seen from +z: of its 4 faces, 1 to 3 face the camera, never all 4.
        let pts = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, -0.5],
            [-1.0, 0.7, -0.5],
            [-1.0, -0.7, -0.5],
        ];
        let out = vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]];
        let inward: Vec<[usize; 3]> = out.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let count = |tris: Vec<[usize; 3]>, closed: bool| {
            let mut m = TriMesh::new(pts, tris);
            if closed {
                m = m.closed();
            }
            Frame::new("t", cam())
                .mesh(m)
                .to_svg()
                .unwrap()
                .matches("<polygon")
                .count()
        };
        assert_eq!(count(out.clone(), false), 4);
        // The apex points at the camera: the three side faces are seen, the base is not.
        assert_eq!(count(out, true), 3);
        assert_eq!(count(inward, true), 3);
    }

    #[test]
    fn wireframe_draws_each_edge_once() {
        let m = TriMesh::new(
            [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .wireframe();
        let svg = Frame::new("t", cam()).mesh(m).to_svg().unwrap();
        assert_eq!(svg.matches("<path").count(), 5);
    }

    #[test]
    fn bad_input_is_an_error_naming_it() {
        let e = Frame::new("t", cam())
            .points(Points::new([[0.0; 3]], 0.1).values("speed", [1.0, 2.0]))
            .to_svg()
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("2 values of \"speed\" for 1 positions"),
            "{e}"
        );
        let e = Frame::new("t", cam())
            .mesh(TriMesh::new([[0.0; 3]], vec![[0, 1, 2]]))
            .to_svg()
            .unwrap_err();
        assert!(e.to_string().contains("indexes past its 1 points"), "{e}");
        let e = Frame::new(
            "t",
            Camera::orthographic([0.0; 3], [0.0; 3], [0.0, 1.0, 0.0]),
        )
        .to_svg()
        .unwrap_err();
        assert!(e.to_string().contains("camera"), "{e}");
    }

    #[test]
    fn the_colour_scale_runs_from_dark_to_bright() {
        assert_eq!(scale_colour(0.0), [68, 1, 84]);
        assert_eq!(scale_colour(1.0), [253, 231, 37]);
        assert_eq!(scale_colour(f64::NAN), [68, 1, 84]);
        let sum = |c: Rgb| c.iter().map(|&v| v as u32).sum::<u32>();
        assert!(sum(scale_colour(0.25)) < sum(scale_colour(0.75)));
    }
}
