//! xatlas's C interface (`vendor/xatlas_c.h`), declared field for field,
//! and the one owner of an `xatlasAtlas`.

use crate::{Atlas, AtlasError, AtlasVertex, MeshInput, PackOptions};
use std::os::raw::{c_char, c_int, c_void};

#[repr(C)]
struct XChart {
    face_array: *mut u32,
    atlas_index: u32,
    face_count: u32,
    kind: c_int,
    material: u32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct XVertex {
    atlas_index: i32,
    chart_index: i32,
    uv: [f32; 2],
    xref: u32,
}

#[repr(C)]
struct XMesh {
    chart_array: *mut XChart,
    index_array: *mut u32,
    vertex_array: *mut XVertex,
    chart_count: u32,
    index_count: u32,
    vertex_count: u32,
}

#[repr(C)]
struct XAtlas {
    image: *mut u32,
    meshes: *mut XMesh,
    utilization: *mut f32,
    width: u32,
    height: u32,
    atlas_count: u32,
    chart_count: u32,
    mesh_count: u32,
    texels_per_unit: f32,
}

#[repr(C)]
struct XMeshDecl {
    vertex_position_data: *const c_void,
    vertex_normal_data: *const c_void,
    vertex_uv_data: *const c_void,
    index_data: *const c_void,
    face_ignore_data: *const bool,
    face_material_data: *const u32,
    face_vertex_count: *const u8,
    vertex_count: u32,
    vertex_position_stride: u32,
    vertex_normal_stride: u32,
    vertex_uv_stride: u32,
    index_count: u32,
    index_offset: i32,
    face_count: u32,
    index_format: c_int,
    epsilon: f32,
}

#[repr(C)]
struct XChartOptions {
    param_func: Option<unsafe extern "C" fn(*const f32, *mut f32, u32, *const u32, u32)>,
    max_chart_area: f32,
    max_boundary_length: f32,
    normal_deviation_weight: f32,
    roundness_weight: f32,
    straightness_weight: f32,
    normal_seam_weight: f32,
    texture_seam_weight: f32,
    max_cost: f32,
    max_iterations: u32,
    use_input_mesh_uvs: bool,
    fix_winding: bool,
}

#[repr(C)]
struct XPackOptions {
    max_chart_size: u32,
    padding: u32,
    texels_per_unit: f32,
    resolution: u32,
    bilinear: bool,
    block_align: bool,
    brute_force: bool,
    create_image: bool,
    rotate_charts_to_axis: bool,
    rotate_charts: bool,
}

const INDEX_FORMAT_UINT32: c_int = 1;
const ADD_MESH_SUCCESS: c_int = 0;

type PrintFunc = Option<unsafe extern "C" fn(*const c_char, ...) -> c_int>;

extern "C" {
    fn xatlasCreate() -> *mut XAtlas;
    fn xatlasDestroy(atlas: *mut XAtlas);
    fn xatlasAddMesh(atlas: *mut XAtlas, decl: *const XMeshDecl, count_hint: u32) -> c_int;
    fn xatlasComputeCharts(atlas: *mut XAtlas, chart: *const XChartOptions);
    fn xatlasPackCharts(atlas: *mut XAtlas, pack: *const XPackOptions);
    fn xatlasSetPrint(print: PrintFunc, verbose: bool);
    fn xatlasMeshDeclInit(decl: *mut XMeshDecl);
    fn xatlasChartOptionsInit(options: *mut XChartOptions);
    fn xatlasPackOptionsInit(options: *mut XPackOptions);
}

/// An `xatlasAtlas`, destroyed on drop.
pub(crate) struct Handle(*mut XAtlas);

impl Drop for Handle {
    fn drop(&mut self) {
        // SAFETY: `self.0` came from `xatlasCreate`, is non-null (checked
        // in `charts`) and is destroyed exactly once, here.
        unsafe { xatlasDestroy(self.0) }
    }
}

impl Handle {
    /// Adds `mesh` (checked by the caller: finite positions, indices in
    /// range, counts within `MAX_ELEMENTS`) and computes its charts.
    pub(crate) fn charts(mesh: MeshInput<'_>) -> Result<Handle, AtlasError> {
        // SAFETY: each init function fills the whole struct it is given
        // (xatlas memcpys a default-constructed C++ struct of the same
        // size, static_assert-ed in xatlas.cpp), so `assume_init` reads
        // initialized memory; the structs are plain data.
        let (mut decl, mut chart) = unsafe {
            let mut d = std::mem::MaybeUninit::<XMeshDecl>::uninit();
            let mut c = std::mem::MaybeUninit::<XChartOptions>::uninit();
            xatlasMeshDeclInit(d.as_mut_ptr());
            xatlasChartOptionsInit(c.as_mut_ptr());
            (d.assume_init(), c.assume_init())
        };
        decl.vertex_position_data = mesh.positions.as_ptr().cast();
        decl.vertex_position_stride = 12;
        decl.vertex_count = mesh.positions.len() as u32;
        decl.index_data = mesh.triangles.as_ptr().cast();
        decl.index_count = 3 * mesh.triangles.len() as u32;
        decl.index_format = INDEX_FORMAT_UINT32;
        chart.fix_winding = true;
        // SAFETY: `xatlasCreate` has no preconditions; a null result is
        // checked before use. `xatlasSetPrint(None, false)` silences
        // xatlas's diagnostics (it only stores the pointer).
        let handle = Handle(unsafe {
            xatlasSetPrint(None, false);
            xatlasCreate()
        });
        if handle.0.is_null() {
            return Err(AtlasError::Output("xatlasCreate returned null".into()));
        }
        // SAFETY: `decl` points into `mesh`'s slices, which outlive this
        // call (xatlas copies the data in AddMesh); strides and counts
        // describe those slices exactly, and every index is below
        // `vertex_count` (checked by the caller).
        let added = unsafe { xatlasAddMesh(handle.0, &decl, 1) };
        if added != ADD_MESH_SUCCESS {
            return Err(AtlasError::Mesh(format!(
                "xatlas refused it (error {added})"
            )));
        }
        // SAFETY: a live atlas with one mesh added; `chart` is fully
        // initialized.
        unsafe { xatlasComputeCharts(handle.0, &chart) };
        Ok(handle)
    }

    /// Packs the charts (again) with `options`.
    pub(crate) fn pack(&mut self, options: &PackOptions) {
        // SAFETY: as in `charts` (the init function fills the struct).
        let mut pack = unsafe {
            let mut p = std::mem::MaybeUninit::<XPackOptions>::uninit();
            xatlasPackOptionsInit(p.as_mut_ptr());
            p.assume_init()
        };
        pack.padding = options.padding;
        pack.texels_per_unit = options.texels_per_unit;
        pack.resolution = options.resolution;
        // Larger charts are scaled down: no single chart outgrows the
        // texture (or the largest side packed).
        pack.max_chart_size = if options.resolution > 0 {
            options.resolution
        } else {
            crate::MAX_SIDE
        };
        pack.bilinear = true;
        // SAFETY: a live atlas whose charts are computed; `pack` is fully
        // initialized. Packing again replaces the previous output.
        unsafe { xatlasPackCharts(self.0, &pack) };
    }

    fn atlas(&self) -> &XAtlas {
        // SAFETY: `self.0` is a live, non-null atlas owned by `self`;
        // xatlas does not mutate it while no xatlas function runs.
        unsafe { &*self.0 }
    }

    /// Number of textures the charts were packed into.
    pub(crate) fn atlas_count(&self) -> u32 {
        self.atlas().atlas_count
    }

    /// Copies the atlas of the one mesh out, checking it against the input
    /// triangle count.
    pub(crate) fn read(&self, mesh: MeshInput<'_>) -> Result<Atlas, AtlasError> {
        let triangles = mesh.triangles.len();
        let a = self.atlas();
        if a.mesh_count != 1 || a.meshes.is_null() {
            return Err(AtlasError::Output(format!("{} meshes", a.mesh_count)));
        }
        // SAFETY: `meshes` points to `mesh_count` (1) meshes owned by the
        // atlas.
        let m = unsafe { &*a.meshes };
        if m.index_count as usize != 3 * triangles
            || m.vertex_array.is_null()
            || m.index_array.is_null()
        {
            return Err(AtlasError::Output(format!(
                "{} indices for {triangles} triangles",
                m.index_count
            )));
        }
        // SAFETY: xatlas's output mesh owns `vertex_count` vertices and
        // `index_count` indices at these non-null pointers, alive as long
        // as the atlas (borrowed through `self`).
        let (verts, idx) = unsafe {
            (
                std::slice::from_raw_parts(m.vertex_array, m.vertex_count as usize),
                std::slice::from_raw_parts(m.index_array, m.index_count as usize),
            )
        };
        let utilization = if a.utilization.is_null() || a.atlas_count == 0 {
            0.0
        } else {
            // SAFETY: `utilization` holds `atlas_count` (≥ 1) values.
            unsafe { *a.utilization }
        };
        copy_out(a, verts, idx, utilization, mesh.positions.len())
    }
}

fn copy_out(
    a: &XAtlas,
    verts: &[XVertex],
    idx: &[u32],
    utilization: f32,
    sources: usize,
) -> Result<Atlas, AtlasError> {
    let n = verts.len() as u32;
    if let Some(bad) = idx.iter().find(|&&i| i >= n) {
        return Err(AtlasError::Output(format!("index {bad} of {n} vertices")));
    }
    // Callers index the input vertices by `source`: never past them.
    if let Some(v) = verts.iter().find(|v| v.xref as usize >= sources) {
        return Err(AtlasError::Output(format!(
            "output vertex from input vertex {} of {sources}",
            v.xref
        )));
    }
    let vertices = verts
        .iter()
        .map(|v| AtlasVertex {
            source: v.xref,
            uv: v.uv,
            chart: v.chart_index.max(0) as u32,
        })
        .collect();
    Ok(Atlas {
        width: a.width,
        height: a.height,
        texels_per_unit: a.texels_per_unit,
        charts: a.chart_count,
        utilization,
        vertices,
        triangles: idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    })
}
