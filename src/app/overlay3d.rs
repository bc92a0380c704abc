//! The 3D overlay on a view, drawn with wgpu through an egui paint callback (as egui's
//! `custom3d_wgpu` demo does). The fitted meshes are projected in the vertex shader with the
//! camera's own model (eq. 10–11, OpenCV distortion), so the overlay lines up with the frame
//! at any zoom.
//!
//! Two passes. `prepare` renders structure ids into an off-screen target with a depth buffer:
//! visible structures depth-tested into the red channel (the front-most one wins, as the fit's
//! labels do), hidden structures into the green channel with no depth test (they lie inside
//! the organ). `paint` then composites that id image over the frame inside egui's pass:
//! translucent fills, crisp opaque contours where the id changes, and for hidden structures a
//! hatched fill with a dashed outline, so the surgeon sees where the tumour lies through the
//! tissue.

use eframe::egui_wgpu::{self, wgpu};
use std::collections::HashMap;
use std::sync::Arc;

/// Structures the style uniform has room for.
pub const MAX_STRUCTURES: usize = 8;

/// One mesh vertex in the camera's coordinates (mm) and its structure id (1-based).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertex {
    pub position_mm: [f32; 3],
    pub id: f32,
}

/// The camera model and where the image sits in the target (see the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CameraUniform {
    /// fx, fy, cx, cy (pixels).
    pub k: [f32; 4],
    /// k1, k2, p1, p2.
    pub distortion: [f32; 4],
    /// Target pixels per image pixel, then the target position of image point (0, 0) (the
    /// corner of the first pixel), unused.
    pub view: [f32; 4],
    /// Target width, height (px), near and far depth (mm).
    pub target: [f32; 4],
}

/// Colours and switches per structure id.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StyleUniform {
    /// rgb (0–1) and fill opacity.
    pub colours: [[f32; 4]; MAX_STRUCTURES],
    /// x: 1 shown, 0 hidden by the user; y: contour opacity.
    pub shown: [[f32; 4]; MAX_STRUCTURES],
}

/// Everything one view's overlay needs this frame.
pub struct OverlayCallback {
    /// Which view (its target is kept between frames).
    pub key: u64,
    pub target_px: [u32; 2],
    pub camera: CameraUniform,
    pub style: StyleUniform,
    pub vertices: Arc<Vec<Vertex>>,
    /// Triangles of visible structures, then of hidden ones.
    pub visible_indices: Arc<Vec<u32>>,
    pub hidden_indices: Arc<Vec<u32>>,
}

fn bytes<T: Copy>(v: &[T]) -> &[u8] {
    // SAFETY: only used on the `#[repr(C)]` plain-old-data types above and on u32, which have
    // no padding and no invalid bit patterns.
    unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, std::mem::size_of_val(v)) }
}

const MESH_SHADER: &str = r#"
struct Cam { k: vec4<f32>, dist: vec4<f32>, view: vec4<f32>, dst: vec4<f32> };
@group(0) @binding(0) var<uniform> cam: Cam;
struct VOut { @builtin(position) pos: vec4<f32>, @location(0) id: f32 };
@vertex fn vs(@location(0) p: vec3<f32>, @location(1) id: f32) -> VOut {
  var o: VOut;
  let z = max(p.z, 1e-3);
  let x = p.x / z;
  let y = p.y / z;
  let r2 = x * x + y * y;
  let radial = 1.0 + cam.dist.x * r2 + cam.dist.y * r2 * r2;
  let xd = x * radial + 2.0 * cam.dist.z * x * y + cam.dist.w * (r2 + 2.0 * x * x);
  let yd = y * radial + cam.dist.z * (r2 + 2.0 * y * y) + 2.0 * cam.dist.w * x * y;
  let u = cam.k.x * xd + cam.k.z;
  let v = cam.k.y * yd + cam.k.w;
  let tx = u * cam.view.x + cam.view.y;
  let ty = v * cam.view.x + cam.view.z;
  let depth = (p.z - cam.dst.z) / (cam.dst.w - cam.dst.z);
  o.pos = vec4<f32>(tx / cam.dst.x * 2.0 - 1.0, 1.0 - ty / cam.dst.y * 2.0, depth, 1.0);
  o.id = id;
  return o;
}
@fragment fn fs(i: VOut) -> @location(0) vec4<f32> {
  let v = i.id / 255.0;
  return vec4<f32>(v, v, 0.0, 1.0);
}
"#;

const COMPOSITE_SHADER: &str = r#"
struct Style { colours: array<vec4<f32>, 8>, shown: array<vec4<f32>, 8> };
@group(0) @binding(0) var<uniform> style: Style;
@group(0) @binding(1) var ids: texture_2d<f32>;
struct VOut { @builtin(position) pos: vec4<f32>, @location(0) uv: vec2<f32> };
@vertex fn vs(@builtin(vertex_index) i: u32) -> VOut {
  var o: VOut;
  let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
  o.pos = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
  o.uv = uv;
  return o;
}
fn id_at(p: vec2<i32>, channel: i32) -> u32 {
  let size = vec2<i32>(textureDimensions(ids));
  let q = clamp(p, vec2<i32>(0), size - vec2<i32>(1));
  let c = textureLoad(ids, q, 0);
  if (channel == 0) { return u32(round(c.r * 255.0)); }
  return u32(round(c.g * 255.0));
}
fn on_edge(p: vec2<i32>, channel: i32, me: u32) -> bool {
  return id_at(p + vec2<i32>(1, 0), channel) != me || id_at(p - vec2<i32>(1, 0), channel) != me
      || id_at(p + vec2<i32>(0, 1), channel) != me || id_at(p - vec2<i32>(0, 1), channel) != me;
}
fn over(dst: vec4<f32>, rgb: vec3<f32>, a: f32) -> vec4<f32> {
  return vec4<f32>(rgb * a, a) + dst * (1.0 - a);
}
@fragment fn fs(i: VOut) -> @location(0) vec4<f32> {
  let size = vec2<f32>(textureDimensions(ids));
  let p = vec2<i32>(floor(i.uv * size));
  var out = vec4<f32>(0.0);
  let vis = id_at(p, 0);
  if (vis > 0u && vis <= 8u && style.shown[vis - 1u].x > 0.5) {
    let c = style.colours[vis - 1u];
    var a = c.a;
    if (on_edge(p, 0, vis)) { a = style.shown[vis - 1u].y; }
    out = over(out, c.rgb, a);
  }
  let hid = id_at(p, 1);
  if (hid > 0u && hid <= 8u && style.shown[hid - 1u].x > 0.5) {
    let c = style.colours[hid - 1u];
    // Hatched fill, dashed outline: unlike any visible structure's style.
    let hatch = ((p.x - p.y) % 9 + 9) % 9 < 3;
    var a = c.a * select(0.35, 1.0, hatch);
    if (on_edge(p, 1, hid)) {
      let dash = ((p.x + p.y) / 6) % 2 == 0;
      a = select(0.25, 1.0, dash) * style.shown[hid - 1u].y;
    }
    out = over(out, c.rgb, a);
  }
  return out;
}
"#;

/// The pipelines, shared by every view; registered once in the render state.
pub struct OverlayResources {
    visible: wgpu::RenderPipeline,
    hidden: wgpu::RenderPipeline,
    composite: wgpu::RenderPipeline,
    camera_layout: wgpu::BindGroupLayout,
    composite_layout: wgpu::BindGroupLayout,
    views: HashMap<u64, ViewTarget>,
}

struct ViewTarget {
    size: [u32; 2],
    ids: wgpu::Texture,
    ids_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    camera_buffer: wgpu::Buffer,
    camera_group: wgpu::BindGroup,
    style_buffer: wgpu::Buffer,
    composite_group: wgpu::BindGroup,
    vertices: Option<(wgpu::Buffer, u64)>,
    indices: Option<(wgpu::Buffer, u64)>,
    counts: (u32, u32),
}

const IDS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Registers the overlay's pipelines in eframe's wgpu render state (once, at start).
pub fn register(render_state: &egui_wgpu::RenderState) {
    let device = &render_state.device;
    let uniform_entry = |binding, visibility| wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let camera_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("overlay camera"),
        entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX)],
    });
    let composite_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("overlay composite"),
        entries: &[
            uniform_entry(0, wgpu::ShaderStages::FRAGMENT),
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
        ],
    });
    let mesh_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("overlay mesh"),
        source: wgpu::ShaderSource::Wgsl(MESH_SHADER.into()),
    });
    let composite_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("overlay composite"),
        source: wgpu::ShaderSource::Wgsl(COMPOSITE_SHADER.into()),
    });
    let mesh_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("overlay mesh"),
        bind_group_layouts: &[Some(&camera_layout)],
        immediate_size: 0,
    });
    let vertex_attributes = [
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32x3,
            offset: 0,
            shader_location: 0,
        },
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32,
            offset: 12,
            shader_location: 1,
        },
    ];
    let mesh_pipeline = |label, depth_test: bool, mask: wgpu::ColorWrites| {
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: Some(&mesh_layout),
            vertex: wgpu::VertexState {
                module: &mesh_module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &vertex_attributes,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(depth_test),
                depth_compare: Some(if depth_test {
                    wgpu::CompareFunction::Less
                } else {
                    wgpu::CompareFunction::Always
                }),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &mesh_module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: IDS_FORMAT,
                    blend: None,
                    write_mask: mask,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
    };
    let visible = mesh_pipeline("overlay visible", true, wgpu::ColorWrites::RED);
    let hidden = mesh_pipeline("overlay hidden", false, wgpu::ColorWrites::GREEN);
    let composite_pipeline_layout =
        device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("overlay composite"),
            bind_group_layouts: &[Some(&composite_layout)],
            immediate_size: 0,
        });
    let composite = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("overlay composite"),
        layout: Some(&composite_pipeline_layout),
        vertex: wgpu::VertexState {
            module: &composite_module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &composite_module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: render_state.target_format,
                blend: Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    });
    render_state
        .renderer
        .write()
        .callback_resources
        .insert(OverlayResources {
            visible,
            hidden,
            composite,
            camera_layout,
            composite_layout,
            views: HashMap::new(),
        });
}

impl OverlayResources {
    fn target(&mut self, device: &wgpu::Device, key: u64, size: [u32; 2]) -> &mut ViewTarget {
        let stale = self.views.get(&key).is_none_or(|t| t.size != size);
        if stale {
            let extent = wgpu::Extent3d {
                width: size[0].max(1),
                height: size[1].max(1),
                depth_or_array_layers: 1,
            };
            let texture = |label, format| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: extent,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
            };
            let ids = texture("overlay ids", IDS_FORMAT);
            let ids_view = ids.create_view(&Default::default());
            let depth_view =
                texture("overlay depth", DEPTH_FORMAT).create_view(&Default::default());
            let buffer = |label, size| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let camera_buffer = buffer(
                "overlay camera",
                std::mem::size_of::<CameraUniform>() as u64,
            );
            let style_buffer = buffer("overlay style", std::mem::size_of::<StyleUniform>() as u64);
            let camera_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("overlay camera"),
                layout: &self.camera_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: camera_buffer.as_entire_binding(),
                }],
            });
            let composite_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("overlay composite"),
                layout: &self.composite_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: style_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&ids_view),
                    },
                ],
            });
            let old = self.views.remove(&key);
            self.views.insert(
                key,
                ViewTarget {
                    size,
                    ids,
                    ids_view,
                    depth_view,
                    camera_buffer,
                    camera_group,
                    style_buffer,
                    composite_group,
                    vertices: old.as_ref().and_then(|o| o.vertices.clone()),
                    indices: old.as_ref().and_then(|o| o.indices.clone()),
                    counts: (0, 0),
                },
            );
        }
        self.views.get_mut(&key).expect("inserted above")
    }
}

/// The structure ids the last `prepare` of view `key` rendered, read back from the GPU: per
/// target pixel (row-major) the front-most visible structure's id (red channel) and the
/// hidden structures' id (green), 0 where none. What the tests compare with the CPU
/// rasteriser, to keep the shader's copy of eq. 10 the same as `Intrinsics::project`.
pub fn read_ids(render_state: &egui_wgpu::RenderState, key: u64) -> Option<Vec<[u8; 2]>> {
    let (device, queue) = (&render_state.device, &render_state.queue);
    let renderer = render_state.renderer.read();
    let target = renderer
        .callback_resources
        .get::<OverlayResources>()?
        .views
        .get(&key)?;
    let [w, h] = target.size;
    let row = (4 * w).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("overlay ids read-back"),
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        target.ids.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).ok()?;
    rx.recv().ok()?.ok()?;
    let data = buffer.get_mapped_range(..).ok()?;
    Some(
        (0..h as usize)
            .flat_map(|y| {
                let line = &data[y * row as usize..][..4 * w as usize];
                line.chunks_exact(4)
                    .map(|px| [px[0], px[1]])
                    .collect::<Vec<_>>()
            })
            .collect(),
    )
}

/// Writes `data` into `slot`, growing the buffer when it is too small.
fn upload(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    slot: &mut Option<(wgpu::Buffer, u64)>,
    data: &[u8],
    usage: wgpu::BufferUsages,
) {
    let need = (data.len() as u64).max(4).next_multiple_of(4);
    if slot.as_ref().is_none_or(|(_, cap)| *cap < need) {
        *slot = Some((
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("overlay mesh"),
                size: need,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            need,
        ));
    }
    if let Some((b, _)) = slot
        && !data.is_empty()
    {
        let mut padded = data.to_vec();
        padded.resize(data.len().next_multiple_of(4), 0);
        queue.write_buffer(b, 0, &padded);
    }
}

impl egui_wgpu::CallbackTrait for OverlayCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(res) = resources.get_mut::<OverlayResources>() else {
            return Vec::new();
        };
        let (visible, hidden) = (res.visible.clone(), res.hidden.clone());
        let target = res.target(device, self.key, self.target_px);
        queue.write_buffer(&target.camera_buffer, 0, bytes(&[self.camera]));
        queue.write_buffer(&target.style_buffer, 0, bytes(&[self.style]));
        upload(
            device,
            queue,
            &mut target.vertices,
            bytes(&self.vertices),
            wgpu::BufferUsages::VERTEX,
        );
        let mut indices = self.visible_indices.to_vec();
        indices.extend_from_slice(&self.hidden_indices);
        upload(
            device,
            queue,
            &mut target.indices,
            bytes(&indices),
            wgpu::BufferUsages::INDEX,
        );
        target.counts = (
            self.visible_indices.len() as u32,
            self.hidden_indices.len() as u32,
        );
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("overlay ids"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target.ids_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &target.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if let (Some((vb, _)), Some((ib, _))) = (&target.vertices, &target.indices) {
            let (nv, nh) = target.counts;
            pass.set_bind_group(0, &target.camera_group, &[]);
            pass.set_vertex_buffer(0, vb.slice(..));
            pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
            if nv > 0 {
                pass.set_pipeline(&visible);
                pass.draw_indexed(0..nv, 0, 0..1);
            }
            if nh > 0 {
                pass.set_pipeline(&hidden);
                pass.draw_indexed(nv..nv + nh, 0, 0..1);
            }
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        let Some(res) = resources.get::<OverlayResources>() else {
            return;
        };
        let Some(target) = res.views.get(&self.key) else {
            return;
        };
        pass.set_pipeline(&res.composite);
        pass.set_bind_group(0, &target.composite_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
