//! glTF 2.0 meshes (`.gltf` with `.bin` files or data URIs, and binary `.glb`).
//!
//! The `gltf` crate parses and validates the document and loads the buffers. Of the materials,
//! the base colour is read (`pbrMetallicRoughness.baseColorFactor` times `baseColorTexture`,
//! glTF 2.0 §3.9.2, with the texture's `TEXCOORD_n` set, its `KHR_texture_transform` and its
//! sampler's wrap modes), times the vertex colours `COLOR_0` where a primitive has them; images
//! are decoded only when a material uses them, from a buffer view (GLB), a data URI or a file next
//! to the glTF. A missing image file is [`Error::Io`] and an undecodable one [`Error::Parse`], both
//! naming the image. Primitives without a material stay material-less (white, or their vertex
//! colours), and a file with neither materials nor vertex colours gives a scene without a surface
//! table. Accessors are read here rather than through
//! the crate's reader, which trusts the file's strides and types and panics on some malformed
//! ones: every range is checked, so a broken file is an error naming it, never a crash.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::buffer::{Data, View};
use ::gltf::json::validation::Checked;
use ::gltf::mesh::{Mode, Semantic};
use ::gltf::{Accessor, Document, Node, Primitive};
use glam::{Mat4, Vec2, Vec3, Vec4};

use super::instances::{available_memory, check_flat_triangles, Instance, InstancedScene};
use super::material::{Material, NO_MATERIAL};
use super::texture::{Texture, Wrap};
use super::{ObjectSurface, Scene};
use crate::{Error, Result};

/// Loads the glTF or GLB file at `path`: every triangle primitive of every mesh instance in the
/// default scene (or in all scenes when none is the default), with node transforms applied.
/// Each primitive instance becomes an object named `mesh/primN`.
pub(super) fn load(path: &Path) -> Result<Scene> {
    load_within(path, available_memory())
}

/// [`load`], refusing to copy meshes that several nodes draw where the copies would not fit in
/// `available` bytes of host memory (`None`: not known, not checked).
fn load_within(path: &Path, available: Option<u64>) -> Result<Scene> {
    let (document, buffers, base) = open(path)?;
    let fail = |message: String| Error::parse(path, None, message);
    let mut scene = Scene::new(path.display().to_string());
    let mut materials = Materials::new(path, &base, &buffers);
    let placed = mesh_instances(&document).map_err(fail)?;
    check_copies(&scene.name, &placed, available)?;
    for (node, transform) in placed {
        let Some(mesh) = node.mesh() else { continue };
        push_mesh(&mut scene, &mesh, transform, &mut materials)?;
    }
    scene.validate()?;
    Ok(scene)
}

/// As [`load`], keeping the nodes that share a mesh as instances of it (issue "Instances"): each
/// mesh a node draws is read once, in its own space (unnamed, so that flattened its objects keep
/// their `mesh/primN` names), and each such node places it with its world transform. Flattened
/// ([`InstancedScene::into_flat`]) it is what [`load`] reads, but for the materials, which each
/// mesh holds its own copy of.
pub(super) fn load_instanced(path: &Path) -> Result<InstancedScene> {
    let (document, buffers, base) = open(path)?;
    let fail = |message: String| Error::parse(path, None, message);
    let mut scene = InstancedScene {
        name: path.display().to_string(),
        ..InstancedScene::default()
    };
    let mut materials = Materials::new(path, &base, &buffers);
    // glTF mesh index → the scene's mesh, or None for one with nothing to trace.
    let mut mesh_of: HashMap<usize, Option<u32>> = HashMap::new();
    for (node, transform) in mesh_instances(&document).map_err(fail)? {
        let Some(mesh) = node.mesh() else { continue };
        let index = match mesh_of.get(&mesh.index()) {
            Some(&index) => index,
            None => {
                let mut own = Scene::new("");
                // Material ids are the mesh's own table's; decoded images stay shared.
                materials.ids.clear();
                push_mesh(&mut own, &mesh, Mat4::IDENTITY, &mut materials)?;
                let index = (own.triangle_count() > 0).then(|| {
                    scene.meshes.push(own);
                    (scene.meshes.len() - 1) as u32
                });
                mesh_of.insert(mesh.index(), index);
                index
            }
        };
        if let Some(mesh) = index {
            scene.instances.push(Instance { mesh, transform });
        }
    }
    if scene.instances.is_empty() {
        return Err(fail(
            "no triangles: nothing in the file can be traced (no faces, or only points and lines)"
                .to_string(),
        ));
    }
    scene.validate()?;
    Ok(scene)
}

/// The document of a glTF file's `bytes` (JSON, or GLB with its binary chunk), checked, and the
/// GLB's binary chunk. gltf 1.4 subtracts the 12-byte header from a GLB's declared length
/// unchecked (a panic in debug builds, a misleading error in release ones): a shorter length is
/// refused here.
fn parse(bytes: &[u8], path: &Path) -> Result<(Document, Option<Vec<u8>>)> {
    if let Some(length) = bytes
        .strip_prefix(b"glTF")
        .and_then(|rest| rest.get(4..8))
        .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]))
        .filter(|&length| length < 12)
    {
        return Err(Error::parse(
            path,
            None,
            format!("GLB header declares a length of {length} bytes, less than the header itself"),
        ));
    }
    let ::gltf::Gltf { document, blob } =
        ::gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| open_error(path, e))?;
    check_position_indices(document.as_json()).map_err(|m| Error::parse(path, None, m))?;
    let document =
        ::gltf::Document::from_json(document.into_json()).map_err(|e| open_error(path, e))?;
    Ok((document, blob))
}

/// The document of the glTF or GLB file at `path`, checked, its buffers loaded, and the folder
/// its relative URIs start from.
fn open(path: &Path) -> Result<(Document, Vec<Data>, std::path::PathBuf)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (document, blob) = parse(&bytes, path)?;
    drop(bytes);
    let base = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    // Buffers named by URI must be regular files too (`/dev/zero` would be read forever), found
    // where the gltf crate's importer will look for them.
    for buffer in document.buffers() {
        if let ::gltf::buffer::Source::Uri(uri) = buffer.source() {
            if !uri.starts_with("data:") {
                let file = resolve_uri(base, uri).map_err(|m| {
                    Error::parse(path, None, format!("buffer {}: {m}", buffer.index()))
                })?;
                let metadata = std::fs::metadata(&file).map_err(|e| {
                    Error::parse(
                        path,
                        None,
                        format!("buffer {}: {}: {e}", buffer.index(), file.display()),
                    )
                })?;
                crate::io::input::regular_file(&file, &metadata)?;
            }
        }
    }
    // A GLB's own buffer is its BIN chunk, which may be padded by up to 3 bytes but never
    // shorter than the buffer says (glTF 2.0 §4.4.3.3): the importer would pad it with zeros,
    // and the last indices or vertices would read 0 unsaid.
    if let (Some(blob), Some(buffer)) = (&blob, document.buffers().next()) {
        if matches!(buffer.source(), ::gltf::buffer::Source::Bin) && blob.len() < buffer.length() {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "buffer 0 is {} bytes, and the BIN chunk holds {}",
                    buffer.length(),
                    blob.len()
                ),
            ));
        }
    }
    let buffers = ::gltf::import_buffers(&document, Some(base), blob).map_err(|e| {
        Error::parse(
            path,
            None,
            format!("cannot load the buffer data it refers to: {e}"),
        )
    })?;
    let base = base.to_path_buf();
    Ok((document, buffers, base))
}

/// Adds `mesh`'s triangle primitives to `scene`, placed by `transform`: each an object named
/// `mesh/primN`, with its material and texture coordinates where it has them.
fn push_mesh(
    scene: &mut Scene,
    mesh: &::gltf::Mesh,
    transform: Mat4,
    materials: &mut Materials,
) -> Result<()> {
    let path = materials.path;
    let fail = |message: String| Error::parse(path, None, message);
    let buffers = materials.buffers;
    let mesh_name = mesh
        .name()
        .map_or_else(|| format!("mesh{}", mesh.index()), str::to_owned);
    for primitive in mesh.primitives() {
        let object = format!("{mesh_name}/prim{}", primitive.index());
        let Some((positions, triangles)) = read_primitive(&primitive, buffers)
            .map_err(|e| fail(format!("mesh {object:?}: {e}")))?
        else {
            continue;
        };
        if triangles.is_empty() {
            continue;
        }
        // A mirroring transform flips orientation; glTF asks loaders to reverse the winding.
        let mirror = transform.determinant() < 0.0;
        let positions: Vec<Vec3> = positions
            .iter()
            .map(|&p| transform.transform_point3(p))
            .collect();
        let material = primitive.material();
        let vertex_colours = read_colours(&primitive, positions.len(), buffers)
            .map_err(|e| fail(format!("mesh {object:?}: {e}")))?;
        if material.index().is_none() && vertex_colours.is_none() {
            let triangles: Vec<[u32; 3]> = triangles
                .into_iter()
                .map(|[a, b, c]| if mirror { [a, c, b] } else { [a, b, c] })
                .collect();
            scene.push_object(object, &positions, &triangles);
            continue;
        }
        let id = materials.id(scene, &material)?;
        let uvs = match material.pbr_metallic_roughness().base_color_texture() {
            Some(info) => {
                let transform = info.texture_transform().map(|t| UvTransform {
                    offset: Vec2::from(t.offset()),
                    rotation: t.rotation(),
                    scale: Vec2::from(t.scale()),
                });
                let set = info
                    .texture_transform()
                    .and_then(|t| t.tex_coord())
                    .unwrap_or(info.tex_coord());
                let uvs = read_texcoords(&primitive, set, positions.len(), buffers)
                    .map_err(|e| fail(format!("mesh {object:?}: {e}")))?;
                match transform {
                    Some(t) => uvs.into_iter().map(|uv| t.apply(uv)).collect(),
                    None => uvs,
                }
            }
            None => vec![Vec2::ZERO; positions.len()],
        };
        let (triangles, uv_of_triangle): (Vec<[u32; 3]>, Vec<[Vec2; 3]>) = triangles
            .into_iter()
            .map(|[a, b, c]| {
                let t = if mirror { [a, c, b] } else { [a, b, c] };
                (t, t.map(|v| uvs[v as usize]))
            })
            .unzip();
        let colour_of_triangle = vertex_colours.map(|colours| {
            triangles
                .iter()
                .map(|t| t.map(|v| colours[v as usize]))
                .collect()
        });
        let surface = ObjectSurface {
            material_of_triangle: vec![id; triangles.len()],
            uv_of_triangle,
            colour_of_triangle,
        };
        scene.push_textured_object(object, &positions, &triangles, surface);
    }
    Ok(())
}

/// The file's materials as scene materials, each added once, its image decoded once.
struct Materials<'a> {
    path: &'a Path,
    base: &'a Path,
    buffers: &'a [Data],
    /// glTF material index → scene material id.
    ids: HashMap<usize, u32>,
    /// glTF image index → decoded image.
    images: HashMap<usize, Arc<Texture>>,
}

impl<'a> Materials<'a> {
    /// None added yet, for the file at `path` whose relative URIs start at `base`.
    fn new(path: &'a Path, base: &'a Path, buffers: &'a [Data]) -> Materials<'a> {
        Materials {
            path,
            base,
            buffers,
            ids: HashMap::new(),
            images: HashMap::new(),
        }
    }

    /// The scene id of `material` (which has an index), adding it on first use.
    fn id(&mut self, scene: &mut Scene, material: &::gltf::Material) -> Result<u32> {
        let Some(index) = material.index() else {
            return Ok(NO_MATERIAL);
        };
        if let Some(&id) = self.ids.get(&index) {
            return Ok(id);
        }
        let pbr = material.pbr_metallic_roughness();
        let mut m = Material::constant(
            material
                .name()
                .map_or_else(|| format!("material{index}"), str::to_owned),
            Vec4::from(pbr.base_color_factor()),
        );
        if let Some(info) = pbr.base_color_texture() {
            let texture = info.texture();
            let sampler = texture.sampler();
            m.wrap = [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())];
            m.texture = Some(self.image(&texture.source())?);
        }
        let id = scene.add_material(m);
        self.ids.insert(index, id);
        Ok(id)
    }

    fn image(&mut self, image: &::gltf::Image) -> Result<Arc<Texture>> {
        if let Some(t) = self.images.get(&image.index()) {
            return Ok(t.clone());
        }
        let what = format!("image {}", image.index());
        let texture = match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let bytes = self
                    .buffers
                    .get(view.buffer().index())
                    .and_then(|b| b.get(view.offset()..view.offset().checked_add(view.length())?))
                    .ok_or_else(|| {
                        Error::parse(
                            self.path,
                            None,
                            format!(
                                "{what}: buffer view {} lies outside its buffer",
                                view.index()
                            ),
                        )
                    })?;
                Texture::decode(bytes, self.path, &what)?
            }
            ::gltf::image::Source::Uri { uri, .. } => match uri.strip_prefix("data:") {
                Some(data) => {
                    let payload = data.split_once(";base64,").map(|(_, p)| p).ok_or_else(|| {
                        Error::parse(
                            self.path,
                            None,
                            format!("{what}: a data URI that is not base64"),
                        )
                    })?;
                    let bytes = base64::decode(payload).map_err(|e| {
                        Error::parse(self.path, None, format!("{what}: bad base64 data URI: {e}"))
                    })?;
                    Texture::decode(&bytes, self.path, &what)?
                }
                None => Texture::load(
                    &resolve_uri(self.base, uri)
                        .map_err(|m| Error::parse(self.path, None, format!("{what}: {m}")))?,
                )?,
            },
        };
        let texture = Arc::new(texture);
        self.images.insert(image.index(), texture.clone());
        Ok(texture)
    }
}

/// The file a glTF URI (not a data URI) names, resolved as the `gltf` crate's importer resolves
/// buffer URIs: `file:` and `file://` give a path as written; any other scheme is unsupported; a
/// relative reference is percent-decoded (RFC 3986 §2.1: exporters write `tex%20base.png`) and
/// taken from the glTF's folder `base`. Errors say what is wrong with the URI.
fn resolve_uri(base: &Path, uri: &str) -> std::result::Result<std::path::PathBuf, String> {
    if let Some(rest) = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))
    {
        return Ok(rest.into());
    }
    if uri.contains(':') {
        return Err(format!("unsupported URI scheme in {uri:?}"));
    }
    let decoded = urlencoding::decode(uri)
        .map_err(|_| format!("URI {uri:?} percent-decodes to invalid UTF-8"))?;
    Ok(base.join(&*decoded))
}

/// `KHR_texture_transform` on a texture reference: texture coordinates are scaled, then rotated
/// by `rotation` radians (counter-clockwise in the (u, v) plane, the image turning clockwise),
/// then offset — `T · R · S` in the extension's own matrices. Affine, so applying it to the
/// corners' coordinates is the same as applying it to any point interpolated between them.
#[derive(Clone, Copy, Debug, PartialEq)]
struct UvTransform {
    offset: Vec2,
    rotation: f32,
    scale: Vec2,
}

impl UvTransform {
    fn apply(&self, uv: Vec2) -> Vec2 {
        let s = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        Vec2::new(cos * s.x + sin * s.y, -sin * s.x + cos * s.y) + self.offset
    }
}

fn wrap(mode: ::gltf::texture::WrappingMode) -> Wrap {
    match mode {
        ::gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        ::gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        ::gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

/// `TEXCOORD_<set>` of a primitive with `n` vertices: float, or normalized unsigned byte or short
/// (glTF 2.0 §3.7.2.1).
fn read_texcoords(
    primitive: &Primitive,
    set: u32,
    n: usize,
    buffers: &[Data],
) -> std::result::Result<Vec<Vec2>, String> {
    let accessor = primitive
        .get(&Semantic::TexCoords(set))
        .ok_or_else(|| format!("its base colour texture uses TEXCOORD_{set}, which it lacks"))?;
    if accessor.dimensions() != Dimensions::Vec2 {
        return Err(format!(
            "TEXCOORD_{set} accessor {} is {:?}, not VEC2",
            accessor.index(),
            accessor.dimensions()
        ));
    }
    let uvs = read_components(&accessor, buffers, 2, n, &format!("TEXCOORD_{set}"))?;
    Ok(uvs.into_iter().map(|c| Vec2::new(c[0], c[1])).collect())
}

/// `COLOR_0` of a primitive with `n` vertices, as linear RGBA (glTF 2.0 §3.7.2.1: VEC3 or VEC4,
/// float or normalized unsigned byte or short; colours are linear, RGB without alpha is opaque),
/// or `None` when it has none. Float colours are clamped to `[0, 1]`, the range the others
/// have, so that a stray negative one cannot make a negative albedo.
fn read_colours(
    primitive: &Primitive,
    n: usize,
    buffers: &[Data],
) -> std::result::Result<Option<Vec<Vec4>>, String> {
    let Some(accessor) = primitive.get(&Semantic::Colors(0)) else {
        return Ok(None);
    };
    let channels = match accessor.dimensions() {
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        other => {
            return Err(format!(
                "COLOR_0 accessor {} is {other:?}, not VEC3 or VEC4",
                accessor.index()
            ))
        }
    };
    let colours = read_components(&accessor, buffers, channels, n, "COLOR_0")?;
    Ok(Some(
        colours
            .into_iter()
            .map(|c| Vec4::from(c).clamp(Vec4::ZERO, Vec4::ONE))
            .collect(),
    ))
}

/// The first `channels` (1 to 4) components of each of the `n` elements of `accessor`, the
/// attribute `what`, as floats (the rest of each array 1): float, or normalized unsigned byte or
/// short, the component types glTF 2.0 allows texture coordinates and colours (§3.7.2.1).
fn read_components(
    accessor: &Accessor,
    buffers: &[Data],
    channels: usize,
    n: usize,
    what: &str,
) -> std::result::Result<Vec<[f32; 4]>, String> {
    let (width, scale) = match (accessor.data_type(), accessor.normalized()) {
        (DataType::F32, _) => (4, 1.0),
        (DataType::U8, true) => (1, 255.0),
        (DataType::U16, true) => (2, 65535.0),
        (other, normalized) => {
            return Err(format!(
                "{what} accessor {} has component type {other:?} (normalized: {normalized}); \
                 expected float or normalized unsigned byte/short",
                accessor.index()
            ))
        }
    };
    let values = read_accessor(accessor, buffers, width * channels, |b| {
        std::array::from_fn(|k| {
            // An element holds `channels` components: past them, `get` finds nothing.
            let Some(c) = b.get(k * width..(k + 1) * width) else {
                return 1.0;
            };
            match width {
                4 => f32_le(c),
                2 => f32::from(u16::from_le_bytes([c[0], c[1]])) / scale,
                _ => f32::from(c[0]) / scale,
            }
        })
    })?;
    if values.len() != n {
        return Err(format!(
            "{what} has {} elements for {n} positions",
            values.len()
        ));
    }
    Ok(values)
}

/// gltf-json 1.4's validator looks up each primitive's POSITION accessor before checking that
/// the index exists, and panics when it does not; so that is checked first, here.
fn check_position_indices(root: &::gltf::json::Root) -> std::result::Result<(), String> {
    let key = Checked::Valid(::gltf::json::mesh::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(i) = primitive.attributes.get(&key) {
                if i.value() >= root.accessors.len() {
                    return Err(format!(
                        "mesh {m} primitive {p}: POSITION accessor {} does not exist \
                         (there are {})",
                        i.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Maps an error from parsing or validating the document; a JSON syntax error in a `.gltf`
/// keeps its line.
fn open_error(path: &Path, e: ::gltf::Error) -> Error {
    let is_glb = path
        .extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("glb"));
    match e {
        ::gltf::Error::Io(e) => Error::io(path, e),
        ::gltf::Error::Deserialize(e) if !is_glb && e.line() > 0 => {
            Error::parse(path, Some(e.line()), e.to_string())
        }
        other => Error::parse(path, None, other.to_string()),
    }
}

/// Whether some mesh of the glTF file at `path` is drawn by more than one node (what
/// [`load_instanced`] keeps as instances), from its document alone: no buffer or image is
/// decoded, so that a caller can pick [`load`] or [`load_instanced`] and read the meshes once.
pub(super) fn shares_a_mesh(path: &Path) -> Result<bool> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (document, _) = parse(&bytes, path)?;
    let placed = mesh_instances(&document).map_err(|m| Error::parse(path, None, m))?;
    Ok(repeats_a_mesh(&placed))
}

/// Whether some mesh is drawn by more than one of the `placed` nodes.
fn repeats_a_mesh(placed: &[(Node, Mat4)]) -> bool {
    let mut drawn = std::collections::HashSet::new();
    placed
        .iter()
        .filter_map(|(node, _)| node.mesh())
        .any(|mesh| !drawn.insert(mesh.index()))
}

/// Refuses, before any mesh is decoded, a file whose nodes draw a mesh more than once where
/// copying each in place would not fit in `available` bytes, as a scene file of instances is
/// refused (`InstancedScene::check_flat_fits`): its triangles as placed counted from the
/// accessors ([`triangles_of`]). A file that draws each mesh once holds what loading it makes,
/// so it is not refused here.
fn check_copies(name: &str, placed: &[(Node, Mat4)], available: Option<u64>) -> Result<()> {
    if !repeats_a_mesh(placed) {
        return Ok(());
    }
    let triangles = placed
        .iter()
        .filter_map(|(node, _)| node.mesh())
        .flat_map(|mesh| {
            mesh.primitives()
                .map(|p| triangles_of(&p))
                .collect::<Vec<_>>()
        })
        .fold(0, u64::saturating_add);
    check_flat_triangles(name, triangles, available)
}

/// The triangles `primitive` adds as [`push_mesh`] reads it, from its accessors' counts alone
/// (no buffer read): a list's index count over 3, a strip's or fan's less 2; none for points
/// and lines, and none for an accessor whose buffer view cannot hold its count (the reader
/// names that fault).
fn triangles_of(primitive: &Primitive) -> u64 {
    let Some(accessor) = primitive
        .indices()
        .or_else(|| primitive.get(&Semantic::Positions))
    else {
        return 0;
    };
    let fits = accessor.view().is_none_or(|view| {
        (accessor.count() as u64)
            .checked_mul(accessor.size() as u64)
            .is_some_and(|bytes| bytes <= view.length() as u64)
    });
    let count = if fits { accessor.count() as u64 } else { 0 };
    match primitive.mode() {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// Every node to draw with its world transform, parents before children. The walk is
/// iterative, so a deep hierarchy cannot overflow the stack, and visits each node at most once
/// per scene: glTF nodes form trees, and a cycle or a node with two parents (which validation
/// does not reject) is reported instead of looping forever or multiplying instances.
fn mesh_instances(document: &Document) -> std::result::Result<Vec<(Node<'_>, Mat4)>, String> {
    let node_count = document.nodes().len();
    let scenes: Vec<Vec<Node>> = match document.default_scene() {
        Some(scene) => vec![scene.nodes().collect()],
        None if document.scenes().len() > 0 => {
            document.scenes().map(|s| s.nodes().collect()).collect()
        }
        // Without scenes, draw the nodes that are nobody's child rather than nothing at all.
        None => {
            let mut is_child = vec![false; node_count];
            for child in document.nodes().flat_map(|n| n.children()) {
                is_child[child.index()] = true;
            }
            vec![document.nodes().filter(|n| !is_child[n.index()]).collect()]
        }
    };
    let mut instances = Vec::new();
    for roots in scenes {
        let mut visited = vec![false; node_count];
        let mut stack: Vec<(Node, Mat4)> = roots
            .into_iter()
            .rev()
            .map(|n| (n, Mat4::IDENTITY))
            .collect();
        while let Some((node, parent)) = stack.pop() {
            if std::mem::replace(&mut visited[node.index()], true) {
                return Err(format!(
                    "node {} is reached twice: the node hierarchy has a cycle or a node with \
                     two parents",
                    node.index()
                ));
            }
            let world = parent * node_matrix(&node)?;
            if node.mesh().is_some() {
                if let Some(fault) = placement_fault(&world) {
                    return Err(format!(
                        "node {}{}: {fault}",
                        node.index(),
                        node_name(&node)
                    ));
                }
            }
            let children: Vec<Node> = node.children().collect();
            stack.extend(children.into_iter().rev().map(|c| (c, world)));
            instances.push((node, world));
        }
    }
    Ok(instances)
}

/// Largest distance from 1 of a node's rotation quaternion's length that [`node_matrix`]
/// normalizes: glTF asks for unit quaternions, and exporters write them to float precision (the
/// Khronos validator's tolerance is of this order); a rotation further off would skew and scale
/// the mesh (`gltf` composes it as if it were unit), so it is refused.
const UNIT_QUATERNION_TOLERANCE: f32 = 1e-3;

/// The node's local transform: its matrix, or its translation, rotation and scale composed,
/// the rotation normalized within [`UNIT_QUATERNION_TOLERANCE`] and refused beyond it.
fn node_matrix(node: &Node) -> std::result::Result<Mat4, String> {
    let transform = match node.transform() {
        ::gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let length = Vec4::from_array(rotation).length();
            // A length that is not a number (an overflowed component) is not unit either.
            let unit = (length - 1.0).abs() <= UNIT_QUATERNION_TOLERANCE;
            if !unit {
                return Err(format!(
                    "node {}{}: its rotation {rotation:?} is not a unit quaternion (length \
                     {length}): glTF rotations are unit quaternions",
                    node.index(),
                    node_name(node)
                ));
            }
            ::gltf::scene::Transform::Decomposed {
                translation,
                rotation: (Vec4::from_array(rotation) / length).to_array(),
                scale,
            }
        }
        matrix => matrix,
    };
    Ok(Mat4::from_cols_array_2d(&transform.matrix()))
}

/// What is wrong with a mesh node's world transform for tracing its mesh, if anything: entries
/// that are not finite, or a last row other than 0 0 0 1 (glTF matrices are affine: a
/// projective one was applied with its last row ignored). A singular transform is allowed here:
/// the flat scene's triangles are then degenerate and traced as nothing, while a two-level scene
/// refuses it (`InstancedScene::validate`), since an instance needs its transform's inverse.
fn placement_fault(world: &Mat4) -> Option<String> {
    if !world.is_finite() {
        return Some(format!(
            "its world transform has entries that are not finite: {world}"
        ));
    }
    (world.row(3) != Vec4::W).then(|| {
        format!(
            "its world transform's last row is {}, not 0 0 0 1: glTF placements are affine",
            world.row(3)
        )
    })
}

/// ` ("name")` for a node with a name, else nothing: for error messages.
fn node_name(node: &Node) -> String {
    node.name().map(|n| format!(" ({n:?})")).unwrap_or_default()
}

/// A primitive's positions and the triangles indexing them.
type Triangles = (Vec<Vec3>, Vec<[u32; 3]>);

/// Reads one primitive, converting strips and fans to triangle lists; `None` for point and
/// line primitives, which a ray caster cannot hit.
fn read_primitive(
    primitive: &Primitive,
    buffers: &[Data],
) -> std::result::Result<Option<Triangles>, String> {
    let mode = primitive.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return Ok(None);
    }
    let accessor = primitive
        .get(&Semantic::Positions)
        .ok_or("it has no POSITION attribute")?;
    let positions = read_positions(&accessor, buffers)?;
    let n = positions.len();
    let indices: Vec<u32> = match primitive.indices() {
        Some(accessor) => read_indices(&accessor, buffers)?,
        None => (0..u32::try_from(n).map_err(|_| "too many vertices")?).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!(
            "index {bad} is out of range: it has only {n} vertices"
        ));
    }
    let triangles = match mode {
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| {
                let (a, b, c) = (indices[i], indices[i + 1], indices[i + 2]);
                // Every other strip triangle is wound backwards; swap to keep one orientation.
                if i % 2 == 0 {
                    [a, b, c]
                } else {
                    [a, c, b]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..indices.len().saturating_sub(1))
            .map(|i| [indices[i], indices[i + 1], indices[0]])
            .collect(),
        _ => {
            // glTF 2.0 §3.7.2.1: a triangle list's count is a multiple of three; the indices
            // left over would be dropped unsaid.
            if indices.len() % 3 != 0 {
                return Err(format!(
                    "its {} indices (or vertices) are not a multiple of 3, as a triangle list's \
                     must be",
                    indices.len()
                ));
            }
            indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect()
        }
    };
    Ok(Some((positions, triangles)))
}

fn read_positions(accessor: &Accessor, buffers: &[Data]) -> std::result::Result<Vec<Vec3>, String> {
    if accessor.data_type() != DataType::F32 || accessor.dimensions() != Dimensions::Vec3 {
        return Err(format!(
            "POSITION accessor {} is {:?} {:?}; only float VEC3 positions are supported",
            accessor.index(),
            accessor.dimensions(),
            accessor.data_type()
        ));
    }
    read_accessor(accessor, buffers, 12, |b| {
        Vec3::new(f32_le(&b[0..4]), f32_le(&b[4..8]), f32_le(&b[8..12]))
    })
}

fn read_indices(accessor: &Accessor, buffers: &[Data]) -> std::result::Result<Vec<u32>, String> {
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(format!(
            "index accessor {} is {:?}, not SCALAR",
            accessor.index(),
            accessor.dimensions()
        ));
    }
    match accessor.data_type() {
        DataType::U8 => read_accessor(accessor, buffers, 1, |b| u32::from(b[0])),
        DataType::U16 => read_accessor(accessor, buffers, 2, |b| {
            u32::from(u16::from_le_bytes([b[0], b[1]]))
        }),
        DataType::U32 => read_accessor(accessor, buffers, 4, |b| {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        }),
        other => Err(format!(
            "index accessor {} has component type {other:?}; expected an unsigned integer",
            accessor.index()
        )),
    }
}

fn f32_le(b: &[u8]) -> f32 {
    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// Decodes every element of `accessor` (each `size` bytes) with `decode`, then applies its
/// sparse substitutions, if any.
fn read_accessor<T: Copy>(
    accessor: &Accessor,
    buffers: &[Data],
    size: usize,
    decode: impl Fn(&[u8]) -> T,
) -> std::result::Result<Vec<T>, String> {
    let what = format!("accessor {}", accessor.index());
    let view = accessor.view().ok_or_else(|| {
        format!("{what} has no buffer view (all-zero sparse accessors are not supported)")
    })?;
    let mut values: Vec<T> = elements(
        &what,
        buffers,
        &view,
        accessor.offset(),
        accessor.count(),
        size,
    )?
    .map(&decode)
    .collect();
    if let Some(sparse) = accessor.sparse() {
        let indices = sparse.indices();
        let index_size = indices.index_type().size();
        let targets = elements(
            &format!("{what}'s sparse indices"),
            buffers,
            &indices.view(),
            indices.offset(),
            sparse.count(),
            index_size,
        )?;
        let substitutes = elements(
            &format!("{what}'s sparse values"),
            buffers,
            &sparse.values().view(),
            sparse.values().offset(),
            sparse.count(),
            size,
        )?;
        for (target, value) in targets.zip(substitutes) {
            let target = target
                .iter()
                .rev()
                .fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
            let slot = values.get_mut(target).ok_or_else(|| {
                format!(
                    "{what} has a sparse index {target} beyond its {} elements",
                    accessor.count()
                )
            })?;
            *slot = decode(value);
        }
    }
    Ok(values)
}

/// The byte slices of `count` elements of `size` bytes at `offset` in `view`, after checking
/// that the view lies in its buffer and the elements in the view.
fn elements<'a>(
    what: &str,
    buffers: &'a [Data],
    view: &View,
    offset: usize,
    count: usize,
    size: usize,
) -> std::result::Result<impl Iterator<Item = &'a [u8]>, String> {
    let buffer = buffers
        .get(view.buffer().index())
        .ok_or_else(|| format!("{what}: buffer {} was not loaded", view.buffer().index()))?;
    let view_bytes = view
        .offset()
        .checked_add(view.length())
        .and_then(|end| buffer.get(view.offset()..end))
        .ok_or_else(|| {
            format!(
                "buffer view {} ({} bytes at {}) lies outside buffer {} ({} bytes)",
                view.index(),
                view.length(),
                view.offset(),
                view.buffer().index(),
                buffer.len()
            )
        })?;
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "{what}: byte stride {stride} is smaller than its {size}-byte elements"
        ));
    }
    let needed = match count {
        0 => Some(0),
        _ => (count - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(size))
            .and_then(|n| n.checked_add(offset)),
    };
    if needed.is_none_or(|n| n > view_bytes.len()) {
        return Err(format!(
            "{what}: {count} elements of {size} bytes (stride {stride}) at offset {offset} \
             do not fit buffer view {} ({} bytes)",
            view.index(),
            view.length()
        ));
    }
    Ok((0..count).map(move |i| &view_bytes[offset + i * stride..][..size]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A glTF file whose `nodes` draw mesh 0 (one indexed triangle, its buffer a data URI).
    fn file(dir: &Path, name: &str, nodes: &str) -> std::path::PathBuf {
        let json = format!(
            r#"{{
  "asset": {{ "version": "2.0" }},
  "scene": 0,
  "scenes": [{{ "nodes": {nodes} }}],
  "nodes": [{{ "mesh": 0 }}, {{ "mesh": 0, "translation": [2, 0, 0] }}],
  "meshes": [{{ "primitives": [{{ "attributes": {{ "POSITION": 0 }}, "indices": 1 }}] }}],
  "buffers": [{{ "byteLength": 56, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAACAPwAAgD8AAAAAAAABAAIAAAA=" }}],
  "bufferViews": [{{ "buffer": 0, "byteLength": 48 }}, {{ "buffer": 0, "byteOffset": 48, "byteLength": 6 }}],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] }},
    {{ "bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR" }}
  ]
}}"#
        );
        let path = dir.join(name);
        std::fs::write(&path, json).unwrap();
        path
    }

    /// Copies of a mesh that several nodes draw are refused where they would not fit, named;
    /// a file that draws each mesh once is what it holds and loads whatever the budget.
    #[test]
    fn copies_of_shared_meshes_are_checked_against_memory() {
        let dir = tempfile::tempdir().unwrap();
        let shared = file(dir.path(), "shared.gltf", "[0, 1]");
        let e = load_within(&shared, Some(100)).unwrap_err().to_string();
        assert!(
            e.contains("shared.gltf") && e.contains("2 triangles as placed"),
            "{e}"
        );
        assert_eq!(load_within(&shared, None).unwrap().triangle_count(), 2);
        assert!(shares_a_mesh(&shared).unwrap());
        let once = file(dir.path(), "once.gltf", "[0]");
        assert_eq!(load_within(&once, Some(100)).unwrap().triangle_count(), 1);
        assert!(!shares_a_mesh(&once).unwrap());
    }
}
