//! Text over the picture: the viewer's readout (hand force, real-time factor, fps) in the
//! built-in 5 × 7 font ([`crate::font`]), drawn as one square per lit font pixel on a dark
//! translucent panel in the top-left corner.
//!
//! A few lines of text are a few thousand squares, built on the CPU every frame in clip space
//! (no texture, no atlas, no font file) and drawn last in the frame's pass, blended and never
//! depth tested. Only a window uses it; offscreen pictures have no overlay and are unchanged.

use bytemuck::{Pod, Zeroable};

use crate::draw::{DEPTH_FORMAT, Growable};
use crate::font::{GLYPH_H, GLYPH_W, glyph};

/// A vertex of the overlay as `overlay.wgsl` reads it: clip-space position and linear colour.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct OverlayVertex {
    position: [f32; 2],
    colour: [f32; 4],
}

impl OverlayVertex {
    const ATTRIBUTES: [wgpu::VertexAttribute; 2] =
        wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x4];
}

/// Text colour (linear) and the panel behind it.
const TEXT: [f32; 4] = [1.0, 1.0, 1.0, 1.0];
const PANEL: [f32; 4] = [0.0, 0.0, 0.0, 0.75];
/// Distance of the panel from the picture's corner and of the text from the panel's edge
/// [screen pixels].
const MARGIN: f32 = 6.0;
const PADDING: f32 = 4.0;

/// Appends the squares of `lines` for a `width × height` picture: the panel, then every lit
/// pixel of every glyph, each font pixel `scale` screen pixels wide.
pub(crate) fn text_quads(
    lines: &[&str],
    width: u32,
    height: u32,
    scale: u32,
    vertices: &mut Vec<OverlayVertex>,
    indices: &mut Vec<u32>,
) {
    let columns = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    if columns == 0 {
        return;
    }
    let s = scale.max(1) as f32;
    let (cell_w, cell_h) = ((GLYPH_W + 1) as f32 * s, (GLYPH_H + 2) as f32 * s);
    let (w, h) = (width.max(1) as f32, height.max(1) as f32);
    // Screen pixels (origin top left, y down) to clip space.
    let clip = |x: f32, y: f32| [2.0 * x / w - 1.0, 1.0 - 2.0 * y / h];
    let mut square = |x0: f32, y0: f32, x1: f32, y1: f32, colour: [f32; 4]| {
        let base = vertices.len() as u32;
        for (x, y) in [(x0, y0), (x0, y1), (x1, y1), (x1, y0)] {
            vertices.push(OverlayVertex {
                position: clip(x, y),
                colour,
            });
        }
        // Counter-clockwise in clip space (y up), though nothing is culled.
        indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    };
    square(
        MARGIN,
        MARGIN,
        MARGIN + 2.0 * PADDING + columns as f32 * cell_w - s,
        MARGIN + 2.0 * PADDING + lines.len() as f32 * cell_h - 2.0 * s,
        PANEL,
    );
    for (row, line) in lines.iter().enumerate() {
        let top = MARGIN + PADDING + row as f32 * cell_h;
        for (col, c) in line.chars().enumerate() {
            let left = MARGIN + PADDING + col as f32 * cell_w;
            for (gy, bits) in glyph(c).iter().enumerate() {
                for gx in 0..GLYPH_W {
                    if bits & (0x10 >> gx) != 0 {
                        let (x, y) = (left + gx as f32 * s, top + gy as f32 * s);
                        square(x, y, x + s, y + s, TEXT);
                    }
                }
            }
        }
    }
}

/// The overlay's pipeline and buffers.
pub(crate) struct OverlayDraw {
    pipeline: wgpu::RenderPipeline,
    vertices: Growable,
    indices: Growable,
    count: u32,
    scratch_vertices: Vec<OverlayVertex>,
    scratch_indices: Vec<u32>,
}

impl OverlayDraw {
    pub(crate) fn new(device: &wgpu::Device, format: wgpu::TextureFormat, samples: u32) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("overlay.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("overlay.wgsl").into()),
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("overlay"),
            bind_group_layouts: &[],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("overlay.wgsl"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<OverlayVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &OverlayVertex::ATTRIBUTES,
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            // The pass has a depth target; the overlay ignores it.
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Always),
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
                    blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        Self {
            pipeline,
            vertices: Growable::new(device, "overlay vertices", wgpu::BufferUsages::VERTEX),
            indices: Growable::new(device, "overlay indices", wgpu::BufferUsages::INDEX),
            count: 0,
            scratch_vertices: Vec::new(),
            scratch_indices: Vec::new(),
        }
    }

    /// Builds and uploads the squares of `lines` for a `width × height` picture.
    pub(crate) fn set_text(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        lines: &[&str],
        width: u32,
        height: u32,
    ) {
        self.scratch_vertices.clear();
        self.scratch_indices.clear();
        // Font pixels twice the screen's on windows of ordinary size, once on small ones.
        let scale = if height >= 480 { 2 } else { 1 };
        text_quads(
            lines,
            width,
            height,
            scale,
            &mut self.scratch_vertices,
            &mut self.scratch_indices,
        );
        self.vertices
            .write(device, queue, bytemuck::cast_slice(&self.scratch_vertices));
        self.indices
            .write(device, queue, bytemuck::cast_slice(&self.scratch_indices));
        self.count = self.scratch_indices.len() as u32;
    }

    /// Records the overlay's draw into `pass`.
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        if self.count > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_vertex_buffer(0, self.vertices.buffer.slice(..));
            pass.set_index_buffer(self.indices.buffer.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..self.count, 0, 0..1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A character's lit pixels become squares inside the panel, inside the picture.
    #[test]
    fn text_becomes_squares_inside_the_panel() {
        let (mut v, mut i) = (Vec::new(), Vec::new());
        text_quads(&["1.0 N", "x"], 200, 100, 1, &mut v, &mut i);
        let lit: u32 = ['1', '.', '0', ' ', 'N', 'x']
            .iter()
            .map(|&c| glyph(c).iter().map(|r| r.count_ones()).sum::<u32>())
            .sum();
        assert_eq!(v.len(), 4 * (1 + lit as usize));
        assert_eq!(i.len(), 6 * (1 + lit as usize));
        let panel = &v[..4];
        let (px0, px1) = (panel[0].position[0], panel[2].position[0]);
        let (py0, py1) = (panel[0].position[1], panel[2].position[1]);
        for vertex in &v[4..] {
            let [x, y] = vertex.position;
            assert!((-1.0..=1.0).contains(&x) && (-1.0..=1.0).contains(&y));
            assert!(x >= px0 && x <= px1 && y <= py0 && y >= py1, "{x} {y}");
        }
        let (mut v, mut i) = (Vec::new(), Vec::new());
        text_quads(&[], 200, 100, 1, &mut v, &mut i);
        assert!(v.is_empty() && i.is_empty());
    }
}
