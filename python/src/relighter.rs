//! `File.relighter()`'s `Relighter`: frames from Python, with the
//! interpreter released while they run.

use crate::arrays;
use crate::errors::{self, value};
use crate::light::{self, Light};
use glam::DVec3;
use ltm_codec::{Limits, LtmFile};
use ltm_relight::{
    Frame, FrameStats, Image, Relight, Request, Source, TermBasis, TexturedMesh, ViewCamera,
    Weighting, MAX_SUPERSAMPLE,
};
use numpy::PyArrayDyn;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Mutex;

/// Wavelet lights per frame when `terms` is not given (`ltm relight`'s
/// default).
pub const DEFAULT_WAVELET_TERMS: usize = 200;

/// A relit image and the stats of its frame, as Python receives them.
type Relit<'py> = (Bound<'py, PyArrayDyn<f32>>, Bound<'py, PyDict>);

/// Relights one opened file; safe to call from several threads at once
/// (each call takes a frame of its own from a pool).
#[pyclass(module = "ltm", name = "Relighter", frozen)]
pub struct Relighter {
    inner: Box<dyn Relight + Send + Sync>,
    /// Frames not in use, reused call after call.
    frames: Mutex<Vec<Frame>>,
    /// The geometry of a texture-space file, for `render`.
    mesh: Option<TexturedMesh>,
}

impl Relighter {
    /// Opens `source` as the relighter of its mode (`ltm_relight::open`).
    pub fn open(
        py: Python<'_>,
        source: Source,
        file: &LtmFile,
        limits: &Limits,
        preload: bool,
    ) -> PyResult<Relighter> {
        py.detach(|| {
            let inner = ltm_relight::open(source, limits)?;
            let mesh = match file.meta().dims.rows.is_texture() {
                true => Some(TexturedMesh::from_file(file, limits)?),
                false => None,
            };
            if preload {
                inner.preload()?;
            }
            Ok(Relighter {
                inner,
                frames: Mutex::new(Vec::new()),
                mesh,
            })
        })
        .map_err(errors::relight)
    }

    /// The request for `terms` (a positive int, "all" or None) and
    /// `weighting`.
    fn request(&self, terms: Option<&Bound<'_, PyAny>>, weighting: &str) -> PyResult<Request> {
        let weighting: Weighting = weighting.parse().map_err(value)?;
        let linear = self.inner.term_basis() == TermBasis::Linear;
        let terms = match terms {
            None if linear => self.inner.max_terms(),
            None => DEFAULT_WAVELET_TERMS,
            // An int first: the usual case, without a failed conversion.
            Some(t) => match t.extract::<i64>() {
                Ok(n) if n >= 1 => n as usize,
                Err(_) if t.extract::<String>().is_ok_and(|s| s == "all") => self.inner.max_terms(),
                _ => {
                    return Err(value(format!(
                        "terms {t}: expected a positive int or 'all'"
                    )))
                }
            },
        };
        Ok(Request { terms, weighting })
    }

    /// One frame under `light`, in a pooled frame; the image is copied out.
    fn frame(&self, light: &[[f32; 3]], request: &Request) -> PyResult<(Image, FrameStats)> {
        let pooled = self.frames.lock().map(|mut f| f.pop()).unwrap_or(None);
        let mut frame = match pooled {
            Some(f) => f,
            None => self.inner.frame().map_err(errors::relight)?,
        };
        let stats = self
            .inner
            .relight(light, request, &mut frame)
            .map_err(errors::relight)?;
        // A copy: the frame keeps its image, whose pages stay mapped and
        // warm for the next frame (a moved-out image made the next frame
        // fault in fresh pages: 15-20 % slower at 1 ms frames).
        let image = Image {
            width: frame.image.width,
            height: frame.image.height,
            data: frame.image.data.clone(),
        };
        if let Ok(mut f) = self.frames.lock() {
            f.push(frame);
        }
        Ok((image, stats))
    }

    /// Reads the light, then relights with the interpreter released.
    fn relit(
        &self,
        py: Python<'_>,
        light: &Bound<'_, PyAny>,
        request: &Request,
        rotation: Option<(f64, f64, f64)>,
    ) -> PyResult<(Image, FrameStats)> {
        let light = Light::extract(light)?;
        let rotation = light::rotation(rotation)?;
        let n = self.inner.face_res();
        py.detach(|| self.frame(&light.cubemap(n, &rotation)?, request))
    }
}

/// A frame's stats as a dict (times in milliseconds); its keys are
/// interned once, not made anew each frame.
fn stats_dict<'py>(py: Python<'py>, s: &FrameStats) -> PyResult<Bound<'py, PyDict>> {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let d = PyDict::new(py);
    d.set_item(intern!(py, "frame_ms"), ms(s.total()))?;
    d.set_item(intern!(py, "light_transform_ms"), ms(s.light_transform))?;
    d.set_item(intern!(py, "selection_ms"), ms(s.selection))?;
    d.set_item(intern!(py, "multiply_ms"), ms(s.multiply))?;
    d.set_item(intern!(py, "inverse_ms"), ms(s.inverse))?;
    d.set_item(intern!(py, "decode_ms"), ms(s.decode))?;
    d.set_item(intern!(py, "columns_decoded"), s.columns_decoded)?;
    d.set_item(intern!(py, "lights"), s.lights)?;
    d.set_item(intern!(py, "nonzeros"), s.nonzeros)?;
    Ok(d)
}

/// A finite 3-vector.
fn vec3(v: (f64, f64, f64), what: &str) -> PyResult<DVec3> {
    let d = DVec3::new(v.0, v.1, v.2);
    match d.is_finite() {
        true => Ok(d),
        false => Err(value(format!(
            "{what} {v:?} has a component that is not finite"
        ))),
    }
}

#[pymethods]
impl Relighter {
    /// The relit image's width and height.
    #[getter]
    fn size(&self) -> (usize, usize) {
        self.inner.size()
    }

    /// The cubemap's face resolution n (lighting of 6·n² texels).
    #[getter]
    fn face_res(&self) -> usize {
        self.inner.face_res()
    }

    /// The largest useful `terms`.
    #[getter]
    fn max_terms(&self) -> usize {
        self.inner.max_terms()
    }

    /// "wavelet" (lights chosen per frame) or "linear" (a fitted basis).
    #[getter]
    fn term_basis(&self) -> &'static str {
        match self.inner.term_basis() {
            TermBasis::Linear => "linear",
            _ => "wavelet",
        }
    }

    /// Decodes every column now, so that later frames only relight.
    fn preload(&self, py: Python<'_>) -> PyResult<()> {
        py.detach(|| self.inner.preload()).map_err(errors::relight)
    }

    /// The lighting as this file's `(6·n², 3)` cubemap (what `relight`
    /// does to a lat-long map or file before each frame).
    #[pyo3(signature = (light, rotation = None))]
    fn cubemap<'py>(
        &self,
        py: Python<'py>,
        light: &Bound<'py, PyAny>,
        rotation: Option<(f64, f64, f64)>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let light = Light::extract(light)?;
        let rotation = light::rotation(rotation)?;
        let n = self.inner.face_res();
        let texels = py.detach(|| light.cubemap(n, &rotation))?;
        arrays::to_numpy(py, arrays::flatten(texels), &[6 * n * n, 3])
    }

    /// Relights under `light`: an `(H, W, 3)` float32 image and the frame's
    /// stats.
    #[pyo3(signature = (light, terms = None, weighting = "unweighted", rotation = None))]
    fn relight<'py>(
        &self,
        py: Python<'py>,
        light: &Bound<'py, PyAny>,
        terms: Option<&Bound<'py, PyAny>>,
        weighting: &str,
        rotation: Option<(f64, f64, f64)>,
    ) -> PyResult<Relit<'py>> {
        let request = self.request(terms, weighting)?;
        let (image, stats) = self.relit(py, light, &request, rotation)?;
        Ok((arrays::image(py, image)?, stats_dict(py, &stats)?))
    }

    /// Texture-space files: relights the texture under `light`, then draws
    /// the mesh from a camera (`ltm render`).
    #[pyo3(signature = (light, camera, target, up = (0.0, 1.0, 0.0), fov = 35.0,
        size = (512, 512), supersample = 3, terms = None, weighting = "unweighted",
        rotation = None))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        light: &Bound<'py, PyAny>,
        camera: (f64, f64, f64),
        target: (f64, f64, f64),
        up: (f64, f64, f64),
        fov: f64,
        size: (u32, u32),
        supersample: u32,
        terms: Option<&Bound<'py, PyAny>>,
        weighting: &str,
        rotation: Option<(f64, f64, f64)>,
    ) -> PyResult<Relit<'py>> {
        let Some(mesh) = &self.mesh else {
            return Err(value(
                "render: this file's rows are image pixels; render draws texture-space files (relight gives the image)",
            ));
        };
        let view = ViewCamera {
            eye: vec3(camera, "camera")?,
            target: vec3(target, "target")?,
            up: vec3(up, "up")?,
            fov,
            width: size.0,
            height: size.1,
        };
        if !(1..=MAX_SUPERSAMPLE).contains(&supersample) {
            return Err(value(format!(
                "supersample = {supersample} is out of range (valid: 1..={MAX_SUPERSAMPLE})"
            )));
        }
        view.validate().map_err(errors::relight)?;
        mesh.check_outside(view.eye).map_err(errors::relight)?;
        let request = self.request(terms, weighting)?;
        let (texture, stats) = self.relit(py, light, &request, rotation)?;
        let image = py
            .detach(|| mesh.render(&texture, &view, supersample))
            .map_err(errors::relight)?;
        Ok((arrays::image(py, image)?, stats_dict(py, &stats)?))
    }
}
