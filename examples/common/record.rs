//! `--rerun <file.rrd>`: a recording of a scene's run for the rerun viewer (`rerun file.rrd`).
//!
//! A scene describes what it shows as a `warp_report::frame::Frame` (the same description its
//! last-frame SVG is drawn from); every few steps it hands one to `Recorder::frame`, which logs
//! the frame's particles (`Points3D`, coloured as the SVG colours them), line sets
//! (`LineStrips3D`) and meshes (`Mesh3D`, or their edges for a wireframe) under stable entity
//! paths, `<scene>/points/<k>`, `<scene>/lines/<k>`, `<scene>/mesh/<k>`, with the title and
//! notes as the text document `<scene>/caption`, on two timelines: `frame` (the scene's step
//! index) and `sim_time` (simulated seconds).
//!
//! Without the `rerun` feature `--rerun` is refused when the command line is parsed (see
//! `parse_rrd_path`), so a recorder is only ever on in a build that can write one.

#![allow(dead_code)] // each example uses its own subset

use std::path::{Path, PathBuf};

use warp_report::frame::Frame;

/// At most this many particles (all sets together) are logged per frame: above it, one in k of
/// each set is (as `Frame` subsamples for its SVG), which bounds a GPU-sized run's file.
pub const MAX_POINTS: usize = 100_000;

/// About how many frames a run records when a scene has no output cadence of its own.
pub const FRAMES: usize = 100;

/// `--rerun`'s value parser: the path, in a build with the `rerun` feature; without it, an
/// error that clap reports against the option (exit status 2), so that the option is never
/// silently ignored.
pub fn parse_rrd_path(text: &str) -> Result<PathBuf, String> {
    if cfg!(feature = "rerun") {
        Ok(PathBuf::from(text))
    } else {
        Err(
            "this build has no rerun support: build the example with `--features rerun` \
             (for instance `cargo run --release --features rerun --example <scene> -- \
             --rerun <file.rrd>`)"
                .to_string(),
        )
    }
}

/// Steps between recorded frames for a run of `steps` steps: about `FRAMES` frames, at least
/// one step apart.
pub fn every(steps: usize) -> usize {
    steps.div_ceil(FRAMES).max(1)
}

/// The stride that keeps one in k of `n` particles so that at most `MAX_POINTS` remain: a
/// scene building a frame per recorded step copies only those into it.
pub fn stride(n: usize) -> usize {
    n.div_ceil(MAX_POINTS).max(1)
}

/// A recording in progress, or nothing (no `--rerun`). Logging and saving happen on rerun's
/// own threads; `finish` waits for them and says what was written.
pub struct Recorder {
    #[cfg(feature = "rerun")]
    inner: Option<imp::Inner>,
}

impl Recorder {
    /// A recorder that records nothing.
    pub fn off() -> Recorder {
        Recorder {
            #[cfg(feature = "rerun")]
            inner: None,
        }
    }

    /// A recording of `scene` into `path` (its folder created if missing), or nothing for
    /// None; an error says why the file cannot be written.
    pub fn new(scene: &str, path: Option<&Path>) -> Result<Recorder, String> {
        let Some(path) = path else {
            return Ok(Recorder::off());
        };
        #[cfg(feature = "rerun")]
        {
            Ok(Recorder {
                inner: Some(imp::Inner::new(scene, path)?),
            })
        }
        #[cfg(not(feature = "rerun"))]
        {
            // `parse_rrd_path` refuses the option in this build; a path here is a caller's bug.
            Err(format!(
                "{scene}: cannot record {}: built without the `rerun` feature",
                path.display()
            ))
        }
    }

    /// Whether frames are recorded (a scene builds a frame for `frame` only then).
    pub fn is_on(&self) -> bool {
        #[cfg(feature = "rerun")]
        {
            self.inner.is_some()
        }
        #[cfg(not(feature = "rerun"))]
        {
            false
        }
    }

    /// Logs `frame` at step `index` and simulated time `time_s` (seconds). A failure is
    /// printed once and ends the recording; the scene goes on.
    pub fn frame(&mut self, index: usize, time_s: f64, frame: &Frame) {
        #[cfg(feature = "rerun")]
        if let Some(inner) = &mut self.inner {
            if let Err(e) = inner.frame(index, time_s, frame) {
                eprintln!(
                    "recording stopped at frame {index}: {e} ({} frames written to {})",
                    inner.frames,
                    inner.path.display()
                );
                self.inner = None;
            }
        }
        #[cfg(not(feature = "rerun"))]
        let _ = (index, time_s, frame);
    }

    /// Writes what is pending, closes the file and prints its path, frame count and size.
    pub fn finish(self) {
        #[cfg(feature = "rerun")]
        if let Some(inner) = self.inner {
            inner.finish();
        }
    }
}

#[cfg(feature = "rerun")]
mod imp {
    use std::path::{Path, PathBuf};

    use warp_report::frame::{Frame, Lines, MeshStyle, Points, TriMesh};

    /// The open recording and what the previous frame logged (so that a set that disappears
    /// is cleared rather than left showing its last state).
    pub struct Inner {
        rec: rerun::RecordingStream,
        scene: String,
        pub path: PathBuf,
        pub frames: usize,
        /// Sets logged by the previous frame: points, lines, meshes.
        counts: [usize; 3],
        view_logged: bool,
    }

    fn f32s(p: [f64; 3]) -> [f32; 3] {
        p.map(|c| c as f32)
    }

    fn finite(p: &[f64; 3]) -> bool {
        p.iter().all(|c| c.is_finite())
    }

    impl Inner {
        pub fn new(scene: &str, path: &Path) -> Result<Inner, String> {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .map_err(|e| format!("creating {}: {e}", dir.display()))?;
            }
            let rec = rerun::RecordingStreamBuilder::new(format!("warp-lang/{scene}"))
                .save(path)
                .map_err(|e| format!("opening {} for the recording: {e}", path.display()))?;
            Ok(Inner {
                rec,
                scene: scene.to_string(),
                path: path.to_path_buf(),
                frames: 0,
                counts: [0; 3],
                view_logged: false,
            })
        }

        pub fn frame(&mut self, index: usize, time_s: f64, frame: &Frame) -> Result<(), String> {
            let rec = &self.rec;
            let scene = &self.scene;
            let err = |what: &str, e: rerun::RecordingStreamError| format!("logging {what}: {e}");
            if !self.view_logged {
                // The scene's up axis, from the camera: rerun's 3-D view orbits around it.
                let up = frame.camera().up;
                let axis = (0..3)
                    .max_by(|&a, &b| up[a].abs().total_cmp(&up[b].abs()))
                    .unwrap_or(2);
                let coordinates = match axis {
                    0 => rerun::ViewCoordinates::RIGHT_HAND_X_UP(),
                    1 => rerun::ViewCoordinates::RIGHT_HAND_Y_UP(),
                    _ => rerun::ViewCoordinates::RIGHT_HAND_Z_UP(),
                };
                rec.log_static(scene.as_str(), &coordinates)
                    .map_err(|e| err("the view coordinates", e))?;
                self.view_logged = true;
            }
            rec.set_time_sequence("frame", index as i64);
            rec.set_duration_secs("sim_time", time_s);

            let mut caption = format!("**{}**", frame.title());
            for note in frame.notes() {
                caption.push_str("\n\n");
                caption.push_str(note);
            }
            rec.log(
                format!("{scene}/caption"),
                &rerun::TextDocument::from_markdown(caption),
            )
            .map_err(|e| err("the caption", e))?;

            // One stride for every set, as the SVG subsamples.
            let total: usize = frame.point_sets().iter().map(|p| p.positions().len()).sum();
            let stride = total.div_ceil(super::MAX_POINTS).max(1);
            for (k, set) in frame.point_sets().iter().enumerate() {
                rec.log(format!("{scene}/points/{k}"), &points(set, stride))
                    .map_err(|e| err(&format!("points {k}"), e))?;
            }
            for (k, lines) in frame.line_sets().iter().enumerate() {
                rec.log(format!("{scene}/lines/{k}"), &line_strips(lines))
                    .map_err(|e| err(&format!("lines {k}"), e))?;
            }
            for (k, m) in frame.meshes().iter().enumerate() {
                let path = format!("{scene}/mesh/{k}");
                let logged = match m.style() {
                    MeshStyle::Shaded => rec.log(path, &mesh(m)?),
                    MeshStyle::Wireframe => rec.log(path, &wireframe(m)),
                };
                logged.map_err(|e| err(&format!("mesh {k}"), e))?;
            }
            // Sets the previous frame had and this one has not.
            let counts = [
                frame.point_sets().len(),
                frame.line_sets().len(),
                frame.meshes().len(),
            ];
            for (kind, (&now, &before)) in ["points", "lines", "mesh"]
                .iter()
                .zip(counts.iter().zip(&self.counts))
            {
                for k in now..before {
                    rec.log(format!("{scene}/{kind}/{k}"), &rerun::Clear::flat())
                        .map_err(|e| err(&format!("clearing {kind} {k}"), e))?;
                }
            }
            self.counts = counts;
            self.frames += 1;
            Ok(())
        }

        pub fn finish(self) {
            let Inner {
                rec, path, frames, ..
            } = self;
            let flushed = rec.flush_blocking();
            // Dropping the last handle closes the file (rerun writes its footer then).
            drop(rec);
            let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            match flushed {
                Ok(()) => println!(
                    "recording: {} ({frames} frames, {:.1} MB; view it with `rerun {}`)",
                    path.display(),
                    size as f64 / 1e6,
                    path.display()
                ),
                Err(e) => println!("recording not completed: {}: {e}", path.display()),
            }
        }
    }

    /// One in `stride` of the set's particles with a finite position, with their colours.
    fn points(set: &Points, stride: usize) -> rerun::Points3D {
        let range = set.value_range();
        let (positions, colours): (Vec<[f32; 3]>, Vec<rerun::Color>) = set
            .positions()
            .iter()
            .enumerate()
            .step_by(stride)
            .filter(|(_, p)| finite(p))
            .map(|(i, &p)| {
                let [r, g, b] = set.colour_of(i, range);
                (f32s(p), rerun::Color::from_rgb(r, g, b))
            })
            .unzip();
        rerun::Points3D::new(positions)
            .with_radii([rerun::Radius::new_scene_units(set.radius() as f32)])
            .with_colors(colours)
    }

    /// The segments as strips: consecutive segments that share an end point join one strip
    /// (a chain or a polyline is one strip, not n two-point ones).
    fn line_strips(lines: &Lines) -> rerun::LineStrips3D {
        let mut strips: Vec<Vec<[f32; 3]>> = Vec::new();
        let mut last_end: Option<[f64; 3]> = None;
        for &[a, b] in lines.segments() {
            if !(finite(&a) && finite(&b)) {
                last_end = None;
                continue;
            }
            match strips.last_mut() {
                Some(strip) if last_end == Some(a) => strip.push(f32s(b)),
                _ => strips.push(vec![f32s(a), f32s(b)]),
            }
            last_end = Some(b);
        }
        let [r, g, b] = lines.rgb();
        rerun::LineStrips3D::new(strips)
            .with_colors([rerun::Color::from_rgb(r, g, b)])
            .with_radii([rerun::Radius::new_ui_points(
                (lines.pixel_width() / 2.0) as f32,
            )])
    }

    /// A shaded mesh, with area-weighted vertex normals so that rerun lights it smoothly.
    fn mesh(m: &TriMesh) -> Result<rerun::Mesh3D, String> {
        let n = m.points().len();
        if let Some(t) = m.triangles().iter().find(|t| t.iter().any(|&i| i >= n)) {
            return Err(format!("mesh triangle {t:?} indexes past its {n} points"));
        }
        let mut normals = vec![[0.0f64; 3]; n];
        for t in m.triangles() {
            let [a, b, c] = t.map(|i| glam::DVec3::from(m.points()[i]));
            // The cross product's length is twice the area: larger faces weigh more.
            let face = (b - a).cross(c - a);
            if face.is_finite() {
                for &i in t {
                    normals[i] = (glam::DVec3::from(normals[i]) + face).to_array();
                }
            }
        }
        let normals = normals
            .into_iter()
            .map(|v| f32s(glam::DVec3::from(v).normalize_or(glam::DVec3::Z).to_array()));
        let [r, g, b] = m.rgb();
        Ok(rerun::Mesh3D::new(m.points().iter().map(|&p| f32s(p)))
            .with_triangle_indices(m.triangles().iter().map(|t| t.map(|i| i as u32)))
            .with_vertex_normals(normals)
            .with_albedo_factor(rerun::datatypes::Rgba32::from_rgb(r, g, b)))
    }

    /// A wireframe mesh: each edge once, as a two-point strip.
    fn wireframe(m: &TriMesh) -> rerun::LineStrips3D {
        let mut seen = std::collections::HashSet::new();
        let mut strips = Vec::new();
        for t in m.triangles() {
            for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                let (Some(&p), Some(&q)) = (m.points().get(i), m.points().get(j)) else {
                    continue; // an index past the points: nothing to join
                };
                if seen.insert((i.min(j), i.max(j))) {
                    strips.push([f32s(p), f32s(q)]);
                }
            }
        }
        let [r, g, b] = m.rgb();
        rerun::LineStrips3D::new(strips)
            .with_colors([rerun::Color::from_rgb(r, g, b)])
            .with_radii([rerun::Radius::new_ui_points(0.5)])
    }
}
