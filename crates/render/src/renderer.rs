//! The offscreen renderer: one device, two pipelines, pictures read back as RGBA bytes.
//!
//! A frame is drawn in one pass (`draw.rs`, shared with the window's
//! [`SurfaceRenderer`](crate::SurfaceRenderer)). With 4 samples
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

use crate::RenderError;
use crate::camera::Camera;
use crate::draw::{Attachments, DEPTH_FORMAT, Gpu, SceneDraw, check_settings, target};
use crate::geometry::{RodPose, SurfaceMesh};

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

/// A buffer that a `width × height` texture of 4-byte texels is copied into and read back
/// from, its rows padded to wgpu's 256-byte copy alignment.
pub(crate) struct Readback {
    buffer: wgpu::Buffer,
    padded_row: u32,
    width: u32,
    height: u32,
}

impl Readback {
    pub(crate) fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let padded_row = (4 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded_row) * u64::from(height),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            buffer,
            padded_row,
            width,
            height,
        }
    }

    /// Records the copy of `texture` into the buffer.
    pub(crate) fn copy(&self, encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture) {
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Submits `encoder` (which must end with [`Readback::copy`]), waits for it and reads the
    /// picture into `out`.
    pub(crate) fn finish(
        &self,
        gpu: &Gpu,
        encoder: wgpu::CommandEncoder,
        out: &mut Image,
    ) -> Result<(), RenderError> {
        let submission = gpu.queue.submit([encoder.finish()]);
        self.buffer.map_async(wgpu::MapMode::Read, .., |_| {});
        gpu.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| RenderError::Device(format!("waiting for the frame: {e}")))?;
        gpu.take_error()?;
        {
            let view = self
                .buffer
                .get_mapped_range(..)
                .map_err(|e| RenderError::Device(format!("reading the frame back: {e}")))?;
            let row = 4 * self.width as usize;
            out.width = self.width;
            out.height = self.height;
            out.rgba.clear();
            out.rgba.reserve(row * self.height as usize);
            for r in view.chunks(self.padded_row as usize) {
                out.rgba.extend_from_slice(&r[..row]);
            }
        }
        self.buffer.unmap();
        Ok(())
    }
}

/// Draws rods and a mesh into pictures, offscreen.
pub struct Renderer {
    gpu: Gpu,
    settings: RenderSettings,
    scene: SceneDraw,
    multisampled: Option<wgpu::TextureView>,
    resolved: wgpu::Texture,
    resolved_view: wgpu::TextureView,
    depth: wgpu::TextureView,
    readback: Readback,
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
        check_settings(&settings)?;
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let gpu = Gpu::acquire(&instance, None, settings.width, settings.height)?;
        let samples = gpu.samples(settings.samples, COLOUR_FORMAT);
        let scene = SceneDraw::new(&gpu.device, COLOUR_FORMAT, samples, &settings)?;
        let (width, height) = (settings.width, settings.height);
        let resolved = target(
            &gpu.device,
            "picture",
            COLOUR_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            width,
            height,
        );
        let resolved_view = resolved.create_view(&Default::default());
        let multisampled = (samples > 1).then(|| {
            target(
                &gpu.device,
                "picture (multisampled)",
                COLOUR_FORMAT,
                samples,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
                width,
                height,
            )
            .create_view(&Default::default())
        });
        let depth = target(
            &gpu.device,
            "depth",
            DEPTH_FORMAT,
            samples,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
            width,
            height,
        )
        .create_view(&Default::default());
        let readback = Readback::new(&gpu.device, width, height);
        Ok(Self {
            gpu,
            settings,
            scene,
            multisampled,
            resolved,
            resolved_view,
            depth,
            readback,
        })
    }

    /// The adapter drawing the pictures, as its driver names it.
    pub fn adapter(&self) -> &str {
        &self.gpu.name
    }

    /// The settings asked for.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Samples per pixel in use: as asked, or chosen for the adapter, and 1 where the adapter
    /// cannot do 4.
    pub fn samples(&self) -> u32 {
        self.scene.samples()
    }

    /// Uploads the mesh drawn behind every later frame (`None` draws none).
    pub fn set_mesh(&mut self, mesh: Option<&SurfaceMesh>) {
        self.scene.set_mesh(&self.gpu.device, mesh);
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
        let mut encoder = self.encode_frame(camera, rods);
        self.readback.copy(&mut encoder, &self.resolved);
        self.readback.finish(&self.gpu, encoder, out)
    }

    /// Draws `rods` (and the mesh) seen by `camera` and waits until the GPU has finished the
    /// frame, without reading it back: what a frame costs to draw, as a window's frame does
    /// before it is shown (`cosserat view --offscreen` times its frames this way).
    ///
    /// # Errors
    /// [`RenderError::Device`] if the device reports an error.
    pub fn draw(&mut self, camera: &Camera, rods: &[RodPose<'_>]) -> Result<(), RenderError> {
        let encoder = self.encode_frame(camera, rods);
        let submission = self.gpu.queue.submit([encoder.finish()]);
        self.gpu
            .device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| RenderError::Device(format!("waiting for the frame: {e}")))?;
        self.gpu.take_error()
    }

    /// The commands that draw `rods` (and the mesh) seen by `camera` into the picture.
    fn encode_frame(&mut self, camera: &Camera, rods: &[RodPose<'_>]) -> wgpu::CommandEncoder {
        self.scene
            .prepare(&self.gpu.device, &self.gpu.queue, camera, rods);
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        self.scene.encode(
            &mut encoder,
            &Attachments {
                colour: &self.resolved_view,
                multisampled: self.multisampled.as_ref(),
                depth: &self.depth,
            },
        );
        encoder
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
