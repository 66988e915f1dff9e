//! The offscreen renderer: one device, two pipelines, pictures read back as RGBA bytes.
//!
//! A frame is drawn in one pass: the opaque tubes first (depth written), then the vessel
//! translucent (alpha blended, depth tested but not written, back faces culled), so the rods
//! show through the wall and the wall never hides the part of a rod behind it. With 4 samples
//! ([`RenderSettings::samples`]) the pass draws into a multisampled target resolved at its end
//! (smooth edges on the thin tubes). Multisampling is cheap on a GPU but not on lavapipe,
//! where a 1280×720 frame took 37 ms with 4 samples against 7.6 ms with one on a busy 2-core
//! machine, and still 24 ms with 4 samples and no mesh (clearing and resolving the
//! multisampled targets, not drawing; `docs/rendering.md`), so by default a software adapter
//! draws with one sample. The colour target is `Rgba8UnormSrgb`: shading and
//! blending happen in linear light and the bytes read back are sRGB, as PNG expects.
//!
//! The vessel is uploaded once ([`Renderer::set_mesh`]); each frame uploads only the rods'
//! tubes. Frames are read back through a buffer with rows padded to wgpu's 256-byte copy
//! alignment and unpadded on the CPU.
//!
//! Same input, same adapter → same bytes: the vertices are built on the CPU in a fixed order,
//! the mesh's triangles are drawn in the order given, and nothing depends on time or on
//! threads.

use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use crate::RenderError;
use crate::camera::Camera;
use crate::geometry::{ROD_COLOURS, RodPose, SurfaceMesh, Vertex, mesh_vertices, push_tube};

/// What every frame of a renderer shares.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Picture width in pixels.
    pub width: u32,
    /// Picture height in pixels.
    pub height: u32,
    /// Samples per pixel: 1, or 4 for antialiased edges (if the adapter cannot, 1 is used);
    /// `None` picks 4 on a GPU and 1 on a software adapter such as lavapipe, where 4 samples
    /// cost three times as much ([`Renderer::samples`] says what was used).
    pub samples: Option<u32>,
    /// The thinnest tube is drawn at least this many pixels in radius, so that a 0.4 mm
    /// guidewire in a 30 cm vessel stays visible; every tube is thickened by the same factor
    /// (a wire stays thinner than its catheter). Tubes already thick enough keep their radius.
    pub min_radius_px: f64,
    /// Normal contact force [N] drawn fully red; lighter touches shade from yellow.
    pub force_scale: f64,
    /// Background colour (sRGB, 0–1).
    pub background: [f64; 3],
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 1280,
            height: 720,
            samples: None,
            min_radius_px: 1.5,
            force_scale: 0.05,
            background: [0.97, 0.97, 0.96],
        }
    }
}

/// A picture: `width × height` pixels, rows top to bottom, 4 bytes (sRGB RGBA) each.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba: Vec<u8>,
}

const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The camera as the shaders read it (`struct Camera` in `tube.wgsl` and `mesh.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CameraUniform {
    view_projection: [[f32; 4]; 4],
    towards_camera: [f32; 4],
    eye: [f32; 4],
}

/// A growable GPU buffer for the vertices or indices of the tubes.
struct Growable {
    buffer: wgpu::Buffer,
    usage: wgpu::BufferUsages,
    label: &'static str,
}

impl Growable {
    fn new(device: &wgpu::Device, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: 1 << 16,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            buffer,
            usage,
            label,
        }
    }

    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        if bytes.len() as u64 > self.buffer.size() {
            self.buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: (bytes.len() as u64).next_power_of_two(),
                usage: self.usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
        }
        if !bytes.is_empty() {
            queue.write_buffer(&self.buffer, 0, bytes);
        }
    }
}

/// The uploaded vessel.
struct MeshBuffers {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    count: u32,
}

/// Draws rods and a mesh into pictures, offscreen.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: String,
    settings: RenderSettings,
    samples: u32,
    errors: Arc<Mutex<Option<String>>>,
    tube_pipeline: wgpu::RenderPipeline,
    mesh_pipeline: wgpu::RenderPipeline,
    camera_buffer: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    multisampled: Option<wgpu::TextureView>,
    resolved: wgpu::Texture,
    resolved_view: wgpu::TextureView,
    depth: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row: u32,
    tube_vertices: Growable,
    tube_indices: Growable,
    mesh: Option<MeshBuffers>,
    scratch_vertices: Vec<Vertex>,
    scratch_indices: Vec<u32>,
}

impl Renderer {
    /// Acquires an adapter (any: a GPU, or Mesa's lavapipe on a machine without one) and
    /// builds the pipelines and targets for `settings`.
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] when wgpu finds no adapter or device;
    /// [`RenderError::Option`] for a zero or oversized picture or a sample count other than
    /// 1 or 4; [`RenderError::Device`] if the device refuses the pipelines.
    pub fn new(settings: RenderSettings) -> Result<Self, RenderError> {
        if !(1..=4 * 4096).contains(&settings.width) || !(1..=4 * 4096).contains(&settings.height) {
            return Err(RenderError::Option {
                option: "size",
                value: format!("{}x{}", settings.width, settings.height),
                expected: "a width and height from 1 to 16384 pixels",
            });
        }
        if let Some(n @ (0 | 2 | 3 | 5..)) = settings.samples {
            return Err(RenderError::Option {
                option: "samples",
                value: n.to_string(),
                expected: "1 or 4",
            });
        }
        if !(settings.force_scale > 0.0 && settings.force_scale.is_finite()) {
            return Err(RenderError::Option {
                option: "force-scale",
                value: settings.force_scale.to_string(),
                expected: "a positive force in newtons",
            });
        }
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let software = info.device_type == wgpu::DeviceType::Cpu
            || info.name.to_ascii_lowercase().contains("llvmpipe");
        let mut samples = settings.samples.unwrap_or(if software { 1 } else { 4 });
        if !adapter
            .get_texture_format_features(COLOUR_FORMAT)
            .flags
            .sample_count_supported(samples)
        {
            samples = 1;
        }
        let limits = wgpu::Limits {
            max_texture_dimension_2d: settings.width.max(settings.height).max(2048),
            ..wgpu::Limits::downlevel_defaults()
        }
        .using_resolution(adapter.limits());
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("cosserat-render"),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| {
            RenderError::NoAdapter(format!("adapter `{}` gave no device: {e}", info.name))
        })?;
        let errors = Arc::new(Mutex::new(None));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut slot = sink.lock().unwrap_or_else(|p| p.into_inner());
            slot.get_or_insert_with(|| e.to_string());
        }));

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("camera"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        let camera_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera"),
            size: std::mem::size_of::<CameraUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("camera"),
            layout: &bind_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: camera_buffer.as_entire_binding(),
            }],
        });
        let tube_pipeline = pipeline(
            &device,
            &layout,
            "tube.wgsl",
            include_str!("tube.wgsl"),
            samples,
            false,
        );
        let mesh_pipeline = pipeline(
            &device,
            &layout,
            "mesh.wgsl",
            include_str!("mesh.wgsl"),
            samples,
            true,
        );
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(RenderError::Device(format!("building the pipelines: {e}")));
        }

        let extent = wgpu::Extent3d {
            width: settings.width,
            height: settings.height,
            depth_or_array_layers: 1,
        };
        let target = |label, format, samples, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: extent,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let resolved = target(
            "picture",
            COLOUR_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let resolved_view = resolved.create_view(&Default::default());
        let multisampled = (samples > 1).then(|| {
            target(
                "picture (multisampled)",
                COLOUR_FORMAT,
                samples,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            )
            .create_view(&Default::default())
        });
        let depth = target(
            "depth",
            DEPTH_FORMAT,
            samples,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        )
        .create_view(&Default::default());
        let padded_row = (4 * settings.width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded_row) * u64::from(settings.height),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let tube_vertices = Growable::new(&device, "tube vertices", wgpu::BufferUsages::VERTEX);
        let tube_indices = Growable::new(&device, "tube indices", wgpu::BufferUsages::INDEX);
        Ok(Self {
            adapter: format!("{} ({:?}, {})", info.name, info.backend, info.driver),
            device,
            queue,
            settings,
            samples,
            errors,
            tube_pipeline,
            mesh_pipeline,
            camera_buffer,
            bind_group,
            multisampled,
            resolved,
            resolved_view,
            depth,
            readback,
            padded_row,
            tube_vertices,
            tube_indices,
            mesh: None,
            scratch_vertices: Vec::new(),
            scratch_indices: Vec::new(),
        })
    }

    /// The adapter drawing the pictures, as its driver names it.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The settings asked for.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Samples per pixel in use: as asked, or chosen for the adapter, and 1 where the adapter
    /// cannot do 4.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Uploads the mesh drawn behind every later frame (`None` draws none).
    pub fn set_mesh(&mut self, mesh: Option<&SurfaceMesh>) {
        self.mesh = mesh.map(|m| {
            let (vertices, indices) = mesh_vertices(m);
            let vb = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("mesh vertices"),
                    contents: bytemuck::cast_slice(&vertices),
                    usage: wgpu::BufferUsages::VERTEX,
                });
            let ib = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("mesh indices"),
                    contents: bytemuck::cast_slice(&indices),
                    usage: wgpu::BufferUsages::INDEX,
                });
            MeshBuffers {
                vertices: vb,
                indices: ib,
                count: indices.len() as u32,
            }
        });
    }

    /// Draws `rods` (and the mesh) seen by `camera` into `out`, resized as needed.
    ///
    /// # Errors
    /// [`RenderError::Device`] if the device reports an error or the picture cannot be read
    /// back.
    pub fn render_into(
        &mut self,
        camera: &Camera,
        rods: &[RodPose<'_>],
        out: &mut Image,
    ) -> Result<(), RenderError> {
        // Every tube is thickened by the factor that brings the thinnest up to the minimum, so
        // that a wire inside a catheter stays thinner than the catheter.
        let min_radius = self.settings.min_radius_px * camera.pixel_size;
        let thinnest = rods
            .iter()
            .map(|r| r.radius)
            .filter(|r| *r > 0.0)
            .fold(f64::INFINITY, f64::min);
        let thicken = if thinnest.is_finite() {
            (min_radius / thinnest).max(1.0)
        } else {
            1.0
        };
        self.scratch_vertices.clear();
        self.scratch_indices.clear();
        for (i, rod) in rods.iter().enumerate() {
            push_tube(
                &RodPose {
                    radius: rod.radius * thicken,
                    ..*rod
                },
                ROD_COLOURS[i % ROD_COLOURS.len()],
                min_radius,
                self.settings.force_scale,
                &mut self.scratch_vertices,
                &mut self.scratch_indices,
            );
        }
        self.tube_vertices.write(
            &self.device,
            &self.queue,
            bytemuck::cast_slice(&self.scratch_vertices),
        );
        self.tube_indices.write(
            &self.device,
            &self.queue,
            bytemuck::cast_slice(&self.scratch_indices),
        );
        let eye = camera.eye.unwrap_or_default();
        let uniform = CameraUniform {
            view_projection: camera.view_projection,
            towards_camera: [
                camera.towards_camera[0],
                camera.towards_camera[1],
                camera.towards_camera[2],
                0.0,
            ],
            eye: [
                eye[0],
                eye[1],
                eye[2],
                f32::from(u8::from(camera.eye.is_some())),
            ],
        };
        self.queue
            .write_buffer(&self.camera_buffer, 0, bytemuck::bytes_of(&uniform));

        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        {
            let [r, g, b] = self.settings.background.map(srgb_to_linear);
            let (view, resolve_target) = match &self.multisampled {
                Some(ms) => (ms, Some(&self.resolved_view)),
                None => (&self.resolved_view, None),
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("frame"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a: 1.0 }),
                        store: if resolve_target.is_some() {
                            wgpu::StoreOp::Discard
                        } else {
                            wgpu::StoreOp::Store
                        },
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth,
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
            pass.set_bind_group(0, &self.bind_group, &[]);
            if !self.scratch_indices.is_empty() {
                pass.set_pipeline(&self.tube_pipeline);
                pass.set_vertex_buffer(0, self.tube_vertices.buffer.slice(..));
                pass.set_index_buffer(
                    self.tube_indices.buffer.slice(..),
                    wgpu::IndexFormat::Uint32,
                );
                pass.draw_indexed(0..self.scratch_indices.len() as u32, 0, 0..1);
            }
            if let Some(mesh) = &self.mesh {
                pass.set_pipeline(&self.mesh_pipeline);
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh.count, 0, 0..1);
            }
        }
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.resolved,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.settings.height),
                },
            },
            wgpu::Extent3d {
                width: self.settings.width,
                height: self.settings.height,
                depth_or_array_layers: 1,
            },
        );
        let submission = self.queue.submit([encoder.finish()]);
        self.readback.map_async(wgpu::MapMode::Read, .., |_| {});
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| RenderError::Device(format!("waiting for the frame: {e}")))?;
        if let Some(e) = self.errors.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(RenderError::Device(e));
        }
        {
            let view = self
                .readback
                .get_mapped_range(..)
                .map_err(|e| RenderError::Device(format!("reading the frame back: {e}")))?;
            let row = 4 * self.settings.width as usize;
            out.width = self.settings.width;
            out.height = self.settings.height;
            out.rgba.clear();
            out.rgba.reserve(row * self.settings.height as usize);
            for r in view.chunks(self.padded_row as usize) {
                out.rgba.extend_from_slice(&r[..row]);
            }
        }
        self.readback.unmap();
        Ok(())
    }

    /// Draws `rods` (and the mesh) seen by `camera` into a new picture.
    ///
    /// # Errors
    /// As [`Renderer::render_into`].
    pub fn render(&mut self, camera: &Camera, rods: &[RodPose<'_>]) -> Result<Image, RenderError> {
        let mut out = Image::default();
        self.render_into(camera, rods, &mut out)?;
        Ok(out)
    }
}

/// A render pipeline for `source` (entry points `vs_main`, `fs_main`): opaque with depth
/// writes, or translucent (alpha blending, depth tested only).
fn pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    label: &str,
    source: &str,
    samples: u32,
    translucent: bool,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &Vertex::ATTRIBUTES,
            })],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: Some(wgpu::Face::Back),
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(!translucent),
            depth_compare: Some(wgpu::CompareFunction::LessEqual),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: samples,
            ..Default::default()
        },
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: COLOUR_FORMAT,
                blend: translucent.then_some(wgpu::BlendState::ALPHA_BLENDING),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The linear value of an sRGB component (the clear colour is given in linear light).
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
