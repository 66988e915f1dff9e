//! Drawing into a window: the same pass as the offscreen [`Renderer`](crate::Renderer), into
//! the window's swap-chain texture.
//!
//! The crate stays free of any windowing library: the caller hands over anything wgpu can make
//! a surface of (a `winit` window in an `Arc`), and the surface's size when it changes. The
//! swap chain's colour format is whatever the window system offers, drawn through an sRGB view
//! of it so that shading and blending happen in linear light as in the pictures
//! `cosserat render` writes; the pipelines are built for that view's format.
//!
//! A screenshot ([`SurfaceRenderer::draw`] with `capture`) draws the same frame a second time
//! into an offscreen texture of the surface's format and reads it back, rather than copying the
//! swap-chain texture, which a window system need not allow to be read.
//!
//! Frames are presented with `AutoVsync` (FIFO where the window system has it): a window
//! never draws faster than the display, and the caller paces frames itself where there is no
//! display to wait for (Xvfb).

use crate::RenderError;
use crate::camera::Camera;
use crate::draw::{Attachments, DEPTH_FORMAT, Gpu, SceneDraw, check_settings, target};
use crate::geometry::{RodPose, SurfaceMesh};
use crate::renderer::{Image, Readback, RenderSettings};

/// What a frame drawn into the window came to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Presented {
    /// The frame is on its way to the screen.
    Shown,
    /// The window gave no texture this time (minimised, resized, timed out); nothing was
    /// drawn, the next frame tries again.
    Skipped,
}

/// Draws rods and a mesh into a window's surface.
pub struct SurfaceRenderer {
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// The format drawn in: the surface's, with sRGB encoding.
    format: wgpu::TextureFormat,
    scene: SceneDraw,
    multisampled: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
}

impl SurfaceRenderer {
    /// Makes a surface of `window`, an adapter that can present to it, and the pipelines for
    /// its format; `settings.width` and `height` are the window's inner size in pixels.
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] when no adapter can present to the window;
    /// [`RenderError::Option`] for bad settings; [`RenderError::Device`] when the surface cannot
    /// be made or the device refuses the pipelines.
    pub fn new(
        window: impl Into<wgpu::SurfaceTarget<'static>>,
        settings: RenderSettings,
    ) -> Result<Self, RenderError> {
        check_settings(&settings)?;
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let surface = instance
            .create_surface(window)
            .map_err(|e| RenderError::Device(format!("making the window's surface: {e}")))?;
        let gpu = Gpu::acquire(&instance, Some(&surface), settings.width, settings.height)?;
        let caps = surface.get_capabilities(&gpu.adapter);
        let surface_format = caps
            .formats
            .iter()
            .copied()
            .find(wgpu::TextureFormat::is_srgb)
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| {
                RenderError::NoAdapter(format!(
                    "adapter `{}` cannot present to this window",
                    gpu.name
                ))
            })?;
        let format = surface_format.add_srgb_suffix();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format: surface_format,
            color_space: Default::default(),
            width: settings.width,
            height: settings.height,
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: if format == surface_format {
                vec![]
            } else {
                vec![format]
            },
        };
        let samples = gpu.samples(settings.samples, format);
        let scene = SceneDraw::new(&gpu.device, format, samples, &settings)?;
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        surface.configure(&gpu.device, &config);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(RenderError::Device(format!("configuring the window: {e}")));
        }
        let (multisampled, depth) = attachments(&gpu.device, format, samples, &config);
        Ok(Self {
            gpu,
            surface,
            config,
            format,
            scene,
            multisampled,
            depth,
        })
    }

    /// The adapter drawing the window, as its driver names it.
    pub fn adapter(&self) -> &str {
        &self.gpu.name
    }

    /// Samples per pixel in use.
    pub fn samples(&self) -> u32 {
        self.scene.samples()
    }

    /// The size drawn, in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }

    /// Follows the window to its new inner size (a zero size, a minimised window, is kept
    /// until the window has pixels again).
    pub fn resize(&mut self, width: u32, height: u32) {
        if width == 0 || height == 0 || (width, height) == self.size() {
            return;
        }
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(&self.gpu.device, &self.config);
        (self.multisampled, self.depth) = attachments(
            &self.gpu.device,
            self.format,
            self.scene.samples(),
            &self.config,
        );
    }

    /// Uploads the mesh drawn behind every later frame (`None` draws none).
    pub fn set_mesh(&mut self, mesh: Option<&SurfaceMesh>) {
        self.scene.set_mesh(&self.gpu.device, mesh);
    }

    /// Sets the lines of text drawn over the top-left corner of every later frame (the
    /// viewer's readout, in a built-in 5 × 7 pixel font); no lines draw none.
    pub fn set_overlay(&mut self, lines: &[&str]) {
        let (w, h) = self.size();
        self.scene
            .set_overlay(&self.gpu.device, &self.gpu.queue, lines, w, h);
    }

    /// Draws `rods` (and the mesh) seen by `camera` into the window and presents it; with
    /// `capture`, the same frame is also read back into it (sRGB RGBA, as PNG expects).
    ///
    /// # Errors
    /// [`RenderError::Device`] if the device reports an error or the surface is lost.
    pub fn draw(
        &mut self,
        camera: &Camera,
        rods: &[RodPose<'_>],
        capture: Option<&mut Image>,
    ) -> Result<Presented, RenderError> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(Presented::Skipped);
            }
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.surface.configure(&self.gpu.device, &self.config);
                return Ok(Presented::Skipped);
            }
            wgpu::CurrentSurfaceTexture::Lost => {
                return Err(RenderError::Device("the window's surface was lost".into()));
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                self.gpu.take_error()?;
                return Err(RenderError::Device(
                    "the window's surface refused to give a texture".into(),
                ));
            }
        };
        self.scene
            .prepare(&self.gpu.device, &self.gpu.queue, camera, rods);
        let view = frame.texture.create_view(&wgpu::TextureViewDescriptor {
            format: Some(self.format),
            ..Default::default()
        });
        let encoder = self.encode_scene("window frame", &view);
        self.gpu.queue.submit([encoder.finish()]);
        self.gpu.queue.present(frame);
        if let Some(out) = capture {
            self.capture(out)?;
        }
        self.gpu.take_error()?;
        Ok(Presented::Shown)
    }

    /// A command encoder that draws the frame prepared last into `colour`.
    fn encode_scene(&self, label: &str, colour: &wgpu::TextureView) -> wgpu::CommandEncoder {
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        self.scene.encode(
            &mut encoder,
            &Attachments {
                colour,
                multisampled: self.multisampled.as_ref(),
                depth: &self.depth,
            },
        );
        encoder
    }

    /// Draws the frame prepared last into an offscreen texture of the surface's format and
    /// reads it back as RGBA.
    fn capture(&mut self, out: &mut Image) -> Result<(), RenderError> {
        let (width, height) = self.size();
        let format = self.format;
        let texture = target(
            &self.gpu.device,
            "screenshot",
            format,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            width,
            height,
        );
        let view = texture.create_view(&Default::default());
        let readback = Readback::new(&self.gpu.device, width, height);
        let mut encoder = self.encode_scene("screenshot", &view);
        readback.copy(&mut encoder, &texture);
        readback.finish(&self.gpu, encoder, out)?;
        if matches!(
            format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        ) {
            for px in out.rgba.chunks_exact_mut(4) {
                px.swap(0, 2);
            }
        }
        Ok(())
    }
}

/// The multisampled colour target (with more than one sample) and the depth target for
/// frames of `config`'s size.
fn attachments(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    samples: u32,
    config: &wgpu::SurfaceConfiguration,
) -> (Option<wgpu::TextureView>, wgpu::TextureView) {
    let (w, h) = (config.width, config.height);
    let multisampled = (samples > 1).then(|| {
        target(
            device,
            "window (multisampled)",
            format,
            samples,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
            w,
            h,
        )
        .create_view(&Default::default())
    });
    let depth = target(
        device,
        "window depth",
        DEPTH_FORMAT,
        samples,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
        w,
        h,
    )
    .create_view(&Default::default());
    (multisampled, depth)
}
