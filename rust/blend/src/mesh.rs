//! Reading a mesh's vertex-group weights (`MDeformVert` arrays) out of Blender's memory.
//!
//! A `Mesh` keeps its per-vertex data in `CustomData vert_data` (stored name `vdata`): an array
//! of `CustomDataLayer`s, each with a `type` and a `data` pointer. The layer of type
//! `CD_MDEFORMVERT` (2) holds one `MDeformVert { MDeformWeight *dw; int totweight; int flag; }`
//! per vertex, and `dw` points to `totweight` pairs `MDeformWeight { int def_nr; float weight; }`
//! in the order Blender stores (and deforms) them. The positions are the layer of type
//! `CD_PROP_FLOAT3` named `position`: one `float[3]` per vertex.
//!
//! Reading through the pointers never makes Blender copy anything: its Python API makes a mesh
//! that shares its arrays with copies of it (duplicates) take its own copy of an array it reads.

use crate::memory::{read, ReadError};
use crate::sdna::{DnaError, Sdna};

/// `eCustomDataType::CD_MDEFORMVERT`, unchanged since Blender 2.5.
const CD_MDEFORMVERT: i32 = 2;
/// `eCustomDataType::CD_PROP_FLOAT3`, the type of the `position` attribute since Blender 3.5.
const CD_PROP_FLOAT3: i32 = 48;
const POSITION: &[u8] = b"position";
/// Sanity bounds: beyond these the memory cannot be a mesh of this layout.
const MAX_LAYERS: i32 = 1 << 16;
const MAX_WEIGHTS_PER_VERTEX: i32 = 1 << 16;

/// Byte offsets of everything [`read_deform_verts`] touches, from an [`Sdna`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshLayout {
    verts_num: usize,
    vert_data: usize,
    layers: usize,
    totlayer: usize,
    layer_size: usize,
    layer_type: usize,
    layer_data: usize,
    layer_name: usize,
    layer_name_len: usize,
    dvert_size: usize,
    dvert_dw: usize,
    dvert_totweight: usize,
    weight_size: usize,
    weight_def_nr: usize,
    weight_weight: usize,
}

impl MeshLayout {
    /// The layout of this Blender's meshes, checked for the field sizes the reader assumes.
    pub fn new(sdna: &Sdna) -> Result<Self, DnaError> {
        let int = |s: &str, names: &[&str]| sdna.number(s, names, 4);
        let ptr = |s: &str, names: &[&str]| sdna.pointer(s, names);
        let vert_data = sdna.field("Mesh", &["vert_data", "vdata"])?;
        if vert_data.pointer || vert_data.size != sdna.struct_size("CustomData")? {
            return Err(DnaError::Inconsistent("Mesh.vert_data is not a CustomData".into()));
        }
        let name = sdna.field("CustomDataLayer", &["name"])?;
        if name.pointer || name.size <= POSITION.len() {
            return Err(DnaError::Inconsistent("CustomDataLayer.name is not a char array".into()));
        }
        Ok(Self {
            verts_num: int("Mesh", &["verts_num", "totvert"])?,
            vert_data: vert_data.offset,
            layers: ptr("CustomData", &["layers"])?,
            totlayer: int("CustomData", &["totlayer"])?,
            layer_size: sdna.struct_size("CustomDataLayer")?,
            layer_type: int("CustomDataLayer", &["type"])?,
            layer_data: ptr("CustomDataLayer", &["data"])?,
            layer_name: name.offset,
            layer_name_len: name.size,
            dvert_size: sdna.struct_size("MDeformVert")?,
            dvert_dw: ptr("MDeformVert", &["dw"])?,
            dvert_totweight: int("MDeformVert", &["totweight"])?,
            weight_size: sdna.struct_size("MDeformWeight")?,
            weight_def_nr: int("MDeformWeight", &["def_nr"])?,
            weight_weight: int("MDeformWeight", &["weight"])?,
        })
    }
}

/// A mesh's vertex-group weights in CSR form: vertex `v` has the pairs
/// `(groups[i], weights[i])` for `i` in `offsets[v]..offsets[v+1]`, in stored order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeformVerts {
    pub offsets: Vec<u32>,
    pub groups: Vec<u32>,
    pub weights: Vec<f32>,
}

/// Reads the vertex-group weights of the `Mesh` at `mesh` (`bpy.types.Mesh.as_pointer()`).
/// `Ok(None)` when the mesh has no weight layer at all (Blender then skips the Armature
/// modifier's vertex-group mask).
///
/// # Safety
/// `mesh` must be the address of a live `Mesh` of the Blender whose SDNA built `layout`, not
/// changed by another thread during the call (Python handlers and operators run while nothing
/// else touches it). Every count is checked against `expected_vertices` and sanity bounds
/// before it is used, so a mismatched layout is reported rather than followed far.
pub unsafe fn read_deform_verts(
    layout: &MeshLayout,
    mesh: usize,
    expected_vertices: usize,
) -> Result<Option<DeformVerts>, ReadError> {
    if mesh == 0 {
        return Err(ReadError::Null);
    }
    // SAFETY: for all reads below, offsets come from the SDNA of this Blender, the mesh pointer
    // is live (caller), and the layer and vertex pointers are read from that mesh after their
    // counts passed the checks.
    unsafe {
        let verts: i32 = read(mesh + layout.verts_num);
        if verts < 0 || verts as usize != expected_vertices {
            return Err(ReadError::VertexCount { expected: expected_vertices, found: verts as i64 });
        }
        let dverts = layer_data(layout, mesh, |layer| read::<i32>(layer + layout.layer_type) == CD_MDEFORMVERT)?;
        if dverts == 0 {
            return Ok(None);
        }
        let n = expected_vertices;
        let mut out = DeformVerts { offsets: Vec::with_capacity(n + 1), groups: Vec::new(), weights: Vec::new() };
        out.offsets.push(0);
        // Two passes: count first, so the arrays are allocated once and every count is checked
        // before anything is followed.
        let mut total = 0usize;
        for v in 0..n {
            let dv = dverts + v * layout.dvert_size;
            let count: i32 = read(dv + layout.dvert_totweight);
            if !(0..MAX_WEIGHTS_PER_VERTEX).contains(&count) || (count > 0 && read::<usize>(dv + layout.dvert_dw) == 0)
            {
                return Err(ReadError::Implausible("weights per vertex"));
            }
            total += count as usize;
        }
        if u32::try_from(total).is_err() {
            return Err(ReadError::Implausible("total weight count"));
        }
        out.groups.reserve_exact(total);
        out.weights.reserve_exact(total);
        for v in 0..n {
            let dv = dverts + v * layout.dvert_size;
            let count = read::<i32>(dv + layout.dvert_totweight) as usize;
            let dw: usize = read(dv + layout.dvert_dw);
            for k in 0..count {
                let w = dw + k * layout.weight_size;
                out.groups.push(read::<u32>(w + layout.weight_def_nr));
                out.weights.push(read::<f32>(w + layout.weight_weight));
            }
            out.offsets.push(out.groups.len() as u32);
        }
        Ok(Some(out))
    }
}

/// The `data` of the mesh's first vertex layer that `matches`, or 0 if none does.
///
/// # Safety
/// `mesh` is a live `Mesh` of `layout`'s Blender (see [`read_deform_verts`]); `matches` is given
/// the address of each layer and may read inside it.
unsafe fn layer_data(layout: &MeshLayout, mesh: usize, matches: impl Fn(usize) -> bool) -> Result<usize, ReadError> {
    // SAFETY: offsets from the SDNA of this Blender, the mesh is live (caller), the layers are
    // read only once their count passed the check.
    unsafe {
        let data = mesh + layout.vert_data;
        let layers: usize = read(data + layout.layers);
        let totlayer: i32 = read(data + layout.totlayer);
        if !(0..MAX_LAYERS).contains(&totlayer) || (totlayer > 0 && layers == 0) {
            return Err(ReadError::Implausible("layer count"));
        }
        for i in 0..totlayer as usize {
            let layer = layers + i * layout.layer_size;
            if matches(layer) {
                return Ok(read(layer + layout.layer_data));
            }
        }
        Ok(0)
    }
}

/// Copies the vertex positions of the `Mesh` at `mesh` (`bpy.types.Mesh.as_pointer()`) into
/// `out` (one per vertex). `Ok(false)` when the mesh keeps no `position` layer among its vertex
/// data (a Blender that stores attributes elsewhere): the caller reads them another way.
///
/// # Safety
/// As for [`read_deform_verts`]: `mesh` is a live `Mesh` of `layout`'s Blender that no other
/// thread changes during the call.
pub unsafe fn read_positions(layout: &MeshLayout, mesh: usize, out: &mut [[f32; 3]]) -> Result<bool, ReadError> {
    // SAFETY: the caller's guarantee, passed on; the slice is only read during this call.
    match unsafe { positions_in_memory(layout, mesh, out.len()) }? {
        Some(found) => {
            out.copy_from_slice(found);
            Ok(true)
        }
        None => Ok(false),
    }
}

/// The vertex positions of the `Mesh` at `mesh` where Blender keeps them, without a copy:
/// `Ok(None)` when the mesh keeps no `position` layer among its vertex data (a Blender that
/// stores attributes elsewhere).
///
/// # Safety
/// As for [`read_deform_verts`], for as long as the returned slice is used (`'a`): `mesh` is a
/// live `Mesh` of `layout`'s Blender, and nothing frees, reallocates or writes its positions
/// meanwhile. Blender's handlers and its evaluation both hold for the time of a call made from
/// them: an evaluation reads original meshes and writes only their evaluated copies.
pub unsafe fn positions_in_memory<'a>(
    layout: &MeshLayout,
    mesh: usize,
    expected_vertices: usize,
) -> Result<Option<&'a [[f32; 3]]>, ReadError> {
    if mesh == 0 {
        return Err(ReadError::Null);
    }
    // SAFETY: as in `read_deform_verts`; the name is compared within the array the SDNA sizes,
    // and the slice covers exactly the vertex count the mesh states, checked first.
    unsafe {
        let verts: i32 = read(mesh + layout.verts_num);
        if verts < 0 || verts as usize != expected_vertices {
            return Err(ReadError::VertexCount { expected: expected_vertices, found: verts as i64 });
        }
        let is_position = |layer: usize| {
            read::<i32>(layer + layout.layer_type) == CD_PROP_FLOAT3 && {
                let name = core::slice::from_raw_parts((layer + layout.layer_name) as *const u8, layout.layer_name_len);
                name.starts_with(POSITION) && name[POSITION.len()] == 0
            }
        };
        let data = layer_data(layout, mesh, is_position)?;
        if data == 0 {
            return Ok((expected_vertices == 0).then_some(&[][..]));
        }
        if data % align_of::<f32>() != 0 {
            return Err(ReadError::Implausible("position array alignment"));
        }
        Ok(Some(core::slice::from_raw_parts(data as *const [f32; 3], expected_vertices)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An SDNA with the structs the reader needs, laid out as in Blender 4.2-5.0.
    fn mesh_sdna(renamed: bool) -> Sdna {
        let (verts, vdata) = if renamed { ("verts_num", "vert_data") } else { ("totvert", "vdata") };
        let mut dna = crate::test_dna::Dna::new();
        dna.opaque("BLI_mempool", 0).opaque("CustomDataExternal", 0).opaque("ImplicitSharingInfoHandle", 0);
        dna.strukt(
            "CustomDataLayer",
            &[
                ("int", "type"),
                ("int", "offset"),
                ("int", "flag"),
                ("int", "active"),
                ("int", "active_rnd"),
                ("int", "active_clone"),
                ("int", "active_mask"),
                ("int", "uid"),
                ("char", "name[68]"),
                ("char", "_pad1[4]"),
                ("void", "*data"),
                ("ImplicitSharingInfoHandle", "*sharing_info"),
            ],
        );
        dna.strukt(
            "CustomData",
            &[
                ("CustomDataLayer", "*layers"),
                ("int", "typemap[53]"),
                ("int", "totlayer"),
                ("int", "maxlayer"),
                ("int", "totsize"),
                ("BLI_mempool", "*pool"),
                ("CustomDataExternal", "*external"),
            ],
        );
        dna.strukt("MDeformWeight", &[("int", "def_nr"), ("float", "weight")]);
        dna.strukt("MDeformVert", &[("MDeformWeight", "*dw"), ("int", "totweight"), ("int", "flag")]);
        dna.strukt("Mesh", &[("char", "_pad0[8]"), ("int", verts), ("int", "flag"), ("CustomData", vdata)]);
        Sdna::parse(&dna.bytes()).unwrap()
    }

    #[repr(C)]
    struct Weight {
        def_nr: u32,
        weight: f32,
    }
    #[repr(C)]
    struct DVert {
        dw: *const Weight,
        totweight: i32,
        flag: i32,
    }
    #[repr(C)]
    struct Layer {
        ty: i32,
        rest: [u8; 100],
        data: *const DVert,
        sharing: usize,
    }
    #[repr(C)]
    struct CData {
        layers: *const Layer,
        typemap: [i32; 53],
        totlayer: i32,
        maxlayer: i32,
        totsize: i32,
        pool: usize,
        external: usize,
    }
    #[repr(C)]
    struct FakeMesh {
        pad: [u8; 8],
        verts: i32,
        flag: i32,
        vdata: CData,
    }

    fn fake(weights: &[Vec<(u32, f32)>], with_layer: bool) -> (FakeMesh, Vec<Layer>, Vec<DVert>, Vec<Vec<Weight>>) {
        let lists: Vec<Vec<Weight>> =
            weights.iter().map(|l| l.iter().map(|&(g, w)| Weight { def_nr: g, weight: w }).collect()).collect();
        let dverts: Vec<DVert> = lists
            .iter()
            .map(|l| DVert {
                dw: if l.is_empty() { core::ptr::null() } else { l.as_ptr() },
                totweight: l.len() as i32,
                flag: 0,
            })
            .collect();
        let mut layers = vec![Layer { ty: 49, rest: [0; 100], data: core::ptr::null(), sharing: 0 }];
        if with_layer {
            layers.push(Layer { ty: CD_MDEFORMVERT, rest: [0; 100], data: dverts.as_ptr(), sharing: 0 });
        }
        let mesh = FakeMesh {
            pad: [0; 8],
            verts: weights.len() as i32,
            flag: 0,
            vdata: CData {
                layers: layers.as_ptr(),
                typemap: [0; 53],
                totlayer: layers.len() as i32,
                maxlayer: 0,
                totsize: 0,
                pool: 0,
                external: 0,
            },
        };
        (mesh, layers, dverts, lists)
    }

    #[test]
    fn layout_matches_the_c_structs() {
        assert_eq!(core::mem::size_of::<Layer>(), 120);
        assert_eq!(core::mem::size_of::<CData>(), 248);
        for renamed in [false, true] {
            let layout = MeshLayout::new(&mesh_sdna(renamed)).unwrap();
            assert_eq!(layout.verts_num, 8);
            assert_eq!(layout.vert_data, 16);
            assert_eq!(layout.totlayer, 8 + 53 * 4);
            assert_eq!(layout.layer_data, 104);
        }
    }

    #[test]
    fn reads_weights_in_stored_order() {
        let layout = MeshLayout::new(&mesh_sdna(false)).unwrap();
        let lists = vec![vec![(2, 0.5), (0, 0.25)], vec![], vec![(1, 1.0)], vec![(0, 0.0), (3, 0.75), (1, 0.125)]];
        let (mesh, _l, _d, _w) = fake(&lists, true);
        // SAFETY: `fake` built a live mesh of this layout; its layers and vertices outlive the read.
        let got = unsafe { read_deform_verts(&layout, &mesh as *const _ as usize, 4) }.unwrap().unwrap();
        assert_eq!(got.offsets, vec![0, 2, 2, 3, 6]);
        assert_eq!(got.groups, vec![2, 0, 1, 0, 3, 1]);
        assert_eq!(got.weights, vec![0.5, 0.25, 1.0, 0.0, 0.75, 0.125]);
    }

    #[test]
    fn no_weight_layer_is_none_and_checks_hold() {
        let layout = MeshLayout::new(&mesh_sdna(true)).unwrap();
        let (mesh, _l, _d, _w) = fake(&[vec![(0, 1.0)]], false);
        let p = &mesh as *const _ as usize;
        // SAFETY: a live mesh of this layout from `fake` (here and in the next two reads, the
        // third with a null pointer, which is refused).
        assert_eq!(unsafe { read_deform_verts(&layout, p, 1) }, Ok(None));
        // SAFETY: as above.
        assert_eq!(unsafe { read_deform_verts(&layout, p, 2) }, Err(ReadError::VertexCount { expected: 2, found: 1 }));
        // SAFETY: as above.
        assert_eq!(unsafe { read_deform_verts(&layout, 0, 2) }, Err(ReadError::Null));
        let (mut bad, _l, _d, _w) = fake(&[vec![(0, 1.0)]], true);
        bad.vdata.totlayer = -3;
        // SAFETY: a live mesh of this layout; the bad count is refused before anything is read
        // through it.
        assert_eq!(
            unsafe { read_deform_verts(&layout, &bad as *const _ as usize, 1) },
            Err(ReadError::Implausible("layer count"))
        );
    }

    fn named(ty: i32, name: &str, data: *const DVert) -> Layer {
        let mut rest = [0u8; 100];
        rest[28..28 + name.len()].copy_from_slice(name.as_bytes()); // name[68] is at byte 32
        Layer { ty, rest, data, sharing: 0 }
    }

    #[test]
    fn reads_the_position_layer_only() {
        let layout = MeshLayout::new(&mesh_sdna(true)).unwrap();
        let want = [[1.0f32, 2.0, 3.0], [-4.0, 5.5, 6.25]];
        let decoy = [[9.0f32; 3]; 2];
        let (mut mesh, _l, _d, _w) = fake(&[vec![], vec![]], false);
        let layers = [
            named(CD_PROP_FLOAT3, "positions", decoy.as_ptr().cast()),
            named(49, "position", decoy.as_ptr().cast()),
            named(CD_PROP_FLOAT3, "position", want.as_ptr().cast()),
        ];
        mesh.vdata.layers = layers.as_ptr();
        mesh.vdata.totlayer = 3;
        let p = &mesh as *const _ as usize;
        let mut out = [[0.0f32; 3]; 2];
        // SAFETY: a live mesh of this layout whose layers point at live arrays of two vertices
        // (here and below; the wrong vertex count is refused before anything is copied).
        assert_eq!(unsafe { read_positions(&layout, p, &mut out) }, Ok(true));
        assert_eq!(out, want);
        let mut three = [[0.0f32; 3]; 3];
        // SAFETY: as above.
        let wrong = unsafe { read_positions(&layout, p, &mut three) };
        assert_eq!(wrong, Err(ReadError::VertexCount { expected: 3, found: 2 }));
        // No float3 layer named "position" left.
        mesh.vdata.totlayer = 2;
        // SAFETY: as above.
        assert_eq!(unsafe { read_positions(&layout, &mesh as *const _ as usize, &mut out) }, Ok(false));
    }

    #[test]
    fn the_positions_in_memory_are_blenders_own_array() {
        let layout = MeshLayout::new(&mesh_sdna(true)).unwrap();
        let want = [[1.0f32, 2.0, 3.0], [-4.0, 5.5, 6.25]];
        let (mut mesh, _l, _d, _w) = fake(&[vec![], vec![]], false);
        let layers = [named(CD_PROP_FLOAT3, "position", want.as_ptr().cast())];
        mesh.vdata.layers = layers.as_ptr();
        mesh.vdata.totlayer = 1;
        let p = &mesh as *const _ as usize;
        // SAFETY: a live mesh of this layout whose layer points at a live array of two vertices,
        // used while both live (here and below; wrong counts are refused before the layers).
        let found = unsafe { positions_in_memory(&layout, p, 2) }.unwrap().unwrap();
        assert_eq!(found, &want);
        assert!(core::ptr::eq(found.as_ptr(), want.as_ptr()), "a view, not a copy");
        // SAFETY: as above.
        let wrong = unsafe { positions_in_memory(&layout, p, 3) };
        assert_eq!(wrong, Err(ReadError::VertexCount { expected: 3, found: 2 }));
        mesh.vdata.totlayer = 0;
        // SAFETY: as above.
        assert_eq!(unsafe { positions_in_memory(&layout, &mesh as *const _ as usize, 2) }, Ok(None));
        // SAFETY: null is refused before any read.
        assert_eq!(unsafe { positions_in_memory(&layout, 0, 2) }, Err(ReadError::Null));
    }

    #[test]
    fn implausible_vertex_data_is_refused() {
        let layout = MeshLayout::new(&mesh_sdna(true)).unwrap();
        let (mesh, _l, mut dverts, _w) = fake(&[vec![(0, 1.0)], vec![(1, 0.5)]], true);
        dverts[1].totweight = -1;
        let (mesh2, _l2, _d2, _w2) = (mesh, (), (), ());
        // Point the layer at the modified vertices.
        let layers = [Layer { ty: CD_MDEFORMVERT, rest: [0; 100], data: dverts.as_ptr(), sharing: 0 }];
        let mut m = mesh2;
        m.vdata.layers = layers.as_ptr();
        m.vdata.totlayer = 1;
        // SAFETY: a live mesh of this layout whose one layer points at live vertices; the bad
        // count is refused before their weights are read.
        assert_eq!(
            unsafe { read_deform_verts(&layout, &m as *const _ as usize, 2) },
            Err(ReadError::Implausible("weights per vertex"))
        );
    }
}
