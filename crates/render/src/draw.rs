//! What every target shares: the device, the two pipelines, the camera uniform, the rods' tubes,
//! the uploaded vessel, and the one render pass that draws them.
//!
//! The offscreen [`Renderer`](crate::Renderer) and the window's
//! [`SurfaceRenderer`](crate::SurfaceRenderer) differ only in where the pass draws (a texture
//! read back, or the window's swap-chain texture) and in its colour format; everything that
//! decides what a picture looks like lives here once, so that a window shows what
//! `cosserat render` writes.
//!
//! A frame is drawn in one pass: the opaque tubes first (depth written), then the vessel
//! translucent (alpha blended, depth tested but not written, back faces culled), so the rods
//! show through the wall and the wall never hides the part of a rod behind it.

use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use crate::RenderError;
use crate::camera::Camera;
use crate::geometry::{ROD_COLOURS, RodPose, SurfaceMesh, Vertex, mesh_vertices, push_tube};
use crate::overlay::OverlayDraw;
use crate::renderer::RenderSettings;

pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The camera as the shaders read it (`struct Camera` in `tube.wgsl` and `mesh.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CameraUniform {
    view_projection: [[f32; 4]; 4],
    towards_camera: [f32; 4],
    eye: [f32; 4],
}

/// A growable GPU buffer for vertices or indices built every frame.
pub(crate) struct Growable {
    pub(crate) buffer: wgpu::Buffer,
    usage: wgpu::BufferUsages,
    label: &'static str,
}

impl Growable {
    pub(crate) fn new(
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
    ) -> Self {
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

    pub(crate) fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
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

/// A device and queue with the adapter's description, and where device errors are collected.
pub(crate) struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) adapter: wgpu::Adapter,
    /// The adapter as its driver names it.
    pub(crate) name: String,
    /// Whether the adapter is a software rasteriser (lavapipe), where multisampling is dear.
    pub(crate) software: bool,
    pub(crate) errors: Arc<Mutex<Option<String>>>,
}

impl Gpu {
    /// Any adapter (a GPU, or Mesa's lavapipe), able to present to `surface` when given, and a
    /// device on it that allows `width × height` targets.
    pub(crate) fn acquire(
        instance: &wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
        width: u32,
        height: u32,
    ) -> Result<Self, RenderError> {
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: surface,
            ..Default::default()
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let software = info.device_type == wgpu::DeviceType::Cpu
            || info.name.to_ascii_lowercase().contains("llvmpipe");
        let limits = wgpu::Limits {
            max_texture_dimension_2d: width.max(height).max(2048),
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
        Ok(Self {
            name: format!("{} ({:?}, {})", info.name, info.backend, info.driver),
            device,
            queue,
            adapter,
            software,
            errors,
        })
    }

    /// Samples per pixel for `asked` (`None`: 4 on a GPU, 1 on a software adapter), 1 where
    /// the adapter cannot multisample `format`.
    pub(crate) fn samples(&self, asked: Option<u32>, format: wgpu::TextureFormat) -> u32 {
        let samples = asked.unwrap_or(if self.software { 1 } else { 4 });
        if self
            .adapter
            .get_texture_format_features(format)
            .flags
            .sample_count_supported(samples)
        {
            samples
        } else {
            1
        }
    }

    /// The first error the device reported since the last call, as a [`RenderError`].
    pub(crate) fn take_error(&self) -> Result<(), RenderError> {
        match self.errors.lock().unwrap_or_else(|p| p.into_inner()).take() {
            Some(e) => Err(RenderError::Device(e)),
            None => Ok(()),
        }
    }
}

/// Checks what every renderer's settings must satisfy, whatever it draws into.
pub(crate) fn check_settings(settings: &RenderSettings) -> Result<(), RenderError> {
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
    Ok(())
}

/// The colour and depth attachments of one frame: `colour` is drawn into directly with one
/// sample, or is where `multisampled` is resolved.
pub(crate) struct Attachments<'a> {
    pub(crate) colour: &'a wgpu::TextureView,
    pub(crate) multisampled: Option<&'a wgpu::TextureView>,
    pub(crate) depth: &'a wgpu::TextureView,
}

/// The pipelines and buffers that draw rods and a mesh into targets of one format and sample
/// count.
pub(crate) struct SceneDraw {
    format: wgpu::TextureFormat,
    samples: u32,
    min_radius_px: f64,
    force_scale: f64,
    background: [f64; 3],
    tube_pipeline: wgpu::RenderPipeline,
    mesh_pipeline: wgpu::RenderPipeline,
    camera_buffer: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    tube_vertices: Growable,
    tube_indices: Growable,
    mesh: Option<MeshBuffers>,
    /// Text over the picture, made on first use (a window's readout; pictures have none).
    overlay: Option<OverlayDraw>,
    scratch_vertices: Vec<Vertex>,
    scratch_indices: Vec<u32>,
}

impl SceneDraw {
    /// Builds the pipelines for colour targets of `format` with `samples` per pixel.
    pub(crate) fn new(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        samples: u32,
        settings: &RenderSettings,
    ) -> Result<Self, RenderError> {
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
            device,
            &layout,
            "tube.wgsl",
            include_str!("tube.wgsl"),
            format,
            samples,
            false,
        );
        let mesh_pipeline = pipeline(
            device,
            &layout,
            "mesh.wgsl",
            include_str!("mesh.wgsl"),
            format,
            samples,
            true,
        );
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(RenderError::Device(format!("building the pipelines: {e}")));
        }
        Ok(Self {
            format,
            samples,
            min_radius_px: settings.min_radius_px,
            force_scale: settings.force_scale,
            background: settings.background,
            tube_pipeline,
            mesh_pipeline,
            camera_buffer,
            bind_group,
            tube_vertices: Growable::new(device, "tube vertices", wgpu::BufferUsages::VERTEX),
            tube_indices: Growable::new(device, "tube indices", wgpu::BufferUsages::INDEX),
            mesh: None,
            overlay: None,
            scratch_vertices: Vec::new(),
            scratch_indices: Vec::new(),
        })
    }

    /// Sets the text drawn over every later frame of a `width × height` target (no lines:
    /// none).
    pub(crate) fn set_overlay(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        lines: &[&str],
        width: u32,
        height: u32,
    ) {
        let (format, samples) = (self.format, self.samples);
        self.overlay
            .get_or_insert_with(|| OverlayDraw::new(device, format, samples))
            .set_text(device, queue, lines, width, height);
    }

    /// Samples per pixel the pipelines draw with.
    pub(crate) fn samples(&self) -> u32 {
        self.samples
    }

    /// Uploads the mesh drawn behind every later frame (`None` draws none).
    pub(crate) fn set_mesh(&mut self, device: &wgpu::Device, mesh: Option<&SurfaceMesh>) {
        self.mesh = mesh.map(|m| {
            let (vertices, indices) = mesh_vertices(m);
            let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("mesh vertices"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
            let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
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

    /// Builds the tubes of `rods` on the CPU and uploads them and `camera`.
    pub(crate) fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        camera: &Camera,
        rods: &[RodPose<'_>],
    ) {
        // Every tube is thickened by the factor that brings the thinnest up to the minimum, so
        // that a wire inside a catheter stays thinner than the catheter.
        let min_radius = self.min_radius_px * camera.pixel_size;
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
                self.force_scale,
                &mut self.scratch_vertices,
                &mut self.scratch_indices,
            );
        }
        self.tube_vertices
            .write(device, queue, bytemuck::cast_slice(&self.scratch_vertices));
        self.tube_indices
            .write(device, queue, bytemuck::cast_slice(&self.scratch_indices));
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
        queue.write_buffer(&self.camera_buffer, 0, bytemuck::bytes_of(&uniform));
    }

    /// Records the frame's pass (what [`SceneDraw::prepare`] uploaded) into `encoder`.
    pub(crate) fn encode(&self, encoder: &mut wgpu::CommandEncoder, targets: &Attachments<'_>) {
        let [r, g, b] = self.background.map(srgb_to_linear);
        let (view, resolve_target) = match targets.multisampled {
            Some(ms) => (ms, Some(targets.colour)),
            None => (targets.colour, None),
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
                view: targets.depth,
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
        if let Some(overlay) = &self.overlay {
            overlay.draw(&mut pass);
        }
    }
}

/// A `width × height` texture for a frame's attachments.
pub(crate) fn target(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    samples: u32,
    usage: wgpu::TextureUsages,
    width: u32,
    height: u32,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: samples,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A render pipeline for `source` (entry points `vs_main`, `fs_main`): opaque with depth
/// writes, or translucent (alpha blending, depth tested only).
fn pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    label: &str,
    source: &str,
    format: wgpu::TextureFormat,
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
                format,
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
