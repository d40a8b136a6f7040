//! `ltm.bake` (a scene to a raw store) and `ltm.reference` (the exact
//! `T·L` of a raw store).

use crate::arrays;
use crate::errors;
use crate::file::limits;
use crate::light::{self, Light};
use crate::progress::Callback;
use ltm_bake::{bake as bake_scene, BakeOptions, Overrides, Scene, SceneDesc};
use ltm_codec::{Progress, RawStore};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Bakes a scene to a raw store (see `ltm.pyi`).
#[pyfunction]
#[pyo3(signature = (scene, out, *, width = None, height = None, face_res = None,
    texel_samples = None, spp = None, progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn bake<'py>(
    py: Python<'py>,
    scene: PathBuf,
    out: PathBuf,
    width: Option<u32>,
    height: Option<u32>,
    face_res: Option<u32>,
    texel_samples: Option<u32>,
    spp: Option<u32>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let overrides = Overrides {
        width,
        height,
        face_res,
        texel_samples,
        spp,
        ..Default::default()
    };
    let callback = Callback::new(progress);
    let report = |s| callback.report(s);
    let result = py.detach(|| {
        let mut desc = SceneDesc::load(&scene)?;
        desc.apply(&overrides)?;
        ltm_codec::output::check_space(&out, desc.transport_bytes())?;
        let built = Scene::build(&desc)?;
        bake_scene(
            &built,
            &out,
            &BakeOptions::default(),
            Progress::new(&report),
        )
    });
    let report = result.map_err(errors::bake)?;
    callback.finish()?;
    let d = PyDict::new(py);
    d.set_item("path", &report.path)?;
    d.set_item("rows_baked", report.rows_baked)?;
    d.set_item("blocks_total", report.blocks_total)?;
    d.set_item("blocks_resumed", report.blocks_resumed)?;
    d.set_item("resume", report.resume.to_string())?;
    d.set_item("shadow_rays", report.rays.shadow_rays)?;
    d.set_item("seconds", report.elapsed.as_secs_f64())?;
    d.set_item("dims", crate::file::dims_dict(py, report.header.dims)?)?;
    Ok(d)
}

/// The exact relit image `T·L` from a raw store (see `ltm.pyi`).
#[pyfunction]
#[pyo3(signature = (raw, light, rotation = None, max_memory = None, progress = None))]
pub fn reference<'py>(
    py: Python<'py>,
    raw: PathBuf,
    light: &Bound<'py, PyAny>,
    rotation: Option<(f64, f64, f64)>,
    max_memory: Option<&Bound<'py, PyAny>>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let light = Light::extract(light)?;
    let rotation = light::rotation(rotation)?;
    let limits = limits(max_memory)?;
    let callback = Callback::new(progress);
    let report = |s| callback.report(s);
    let image = py.detach(|| -> PyResult<_> {
        let store = RawStore::open_with_limits(&raw, &limits).map_err(errors::codec)?;
        let cube = light.cubemap(store.dims().face_res() as usize, &rotation)?;
        ltm_relight::reference_with_progress(&store, &cube, Progress::new(&report))
            .map_err(errors::relight)
    })?;
    callback.finish()?;
    arrays::image(py, image)
}
