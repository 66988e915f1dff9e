//! Pictures to files: PNG frames, and one animated file of them.
//!
//! PNG frames are written with the fast deflate setting: a frame of a run is mostly flat
//! background and a translucent wall, which compresses well at any level, and the slower
//! levels would cost more than the drawing itself over a thousand frames.
//!
//! The animation is an MP4 (H.264) piped through `ffmpeg` when it is on the `PATH`, which is
//! small and plays everywhere; without ffmpeg it is an animated GIF. A GIF holds 256 colours,
//! and the usual way to pick them (NeuQuant, per frame) costs about a tenth of a second per
//! 720p frame; a fixed palette (6 levels of red, 7 of green, 6 of blue and 4 greys) with a 4×4
//! ordered dither costs a few milliseconds, keeps every frame on the same palette (no flicker)
//! and is deterministic. Because the dither depends only on a pixel's colour and position, a
//! pixel that did not change keeps its palette index, so each frame after the first stores only
//! the rectangle that changed since the one before (drawn over it, `DisposalMethod::Keep`): in a
//! run the vessel and the background stay still and only the rods move, and the rectangle is a
//! small part of the picture.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use crate::{Image, RenderError};

/// Writes `image` as an 8-bit RGBA PNG at `path`.
///
/// # Errors
/// [`RenderError::Io`] or [`RenderError::Encode`] naming the file.
pub fn write_png(path: &Path, image: &Image) -> Result<(), RenderError> {
    let file = File::create(path).map_err(RenderError::io(path))?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), image.width, image.height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    encoder.set_filter(png::FilterType::Sub);
    let encode = |e: png::EncodingError| RenderError::Encode {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut writer = encoder.write_header().map_err(encode)?;
    writer.write_image_data(&image.rgba).map_err(encode)?;
    writer.finish().map_err(encode)
}

/// Reads an 8-bit RGB or RGBA PNG (what [`write_png`] writes) into an RGBA picture.
///
/// # Errors
/// [`RenderError::Io`] if the file cannot be opened; [`RenderError::Encode`] if it is not
/// such a PNG.
pub fn read_png(path: &Path) -> Result<Image, RenderError> {
    let file = File::open(path).map_err(RenderError::io(path))?;
    let bad = |message: String| RenderError::Encode {
        path: path.to_path_buf(),
        message,
    };
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .map_err(|e| bad(e.to_string()))?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| bad(e.to_string()))?;
    if info.bit_depth != png::BitDepth::Eight {
        return Err(bad(format!(
            "{:?} bits per channel, expected 8",
            info.bit_depth
        )));
    }
    let pixels = (info.width * info.height) as usize;
    let rgba = match info.color_type {
        png::ColorType::Rgba => buf[..pixels * 4].to_vec(),
        png::ColorType::Rgb => buf[..pixels * 3]
            .chunks(3)
            .flat_map(|c| [c[0], c[1], c[2], 255])
            .collect(),
        other => return Err(bad(format!("colour type {other:?}, expected RGB or RGBA"))),
    };
    Ok(Image {
        width: info.width,
        height: info.height,
        rgba,
    })
}

/// The kind of animated file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimationFormat {
    /// H.264 in MP4, through the `ffmpeg` command.
    Mp4,
    /// Animated GIF, written here.
    Gif,
}

impl AnimationFormat {
    /// MP4 when `ffmpeg` runs, else GIF.
    pub fn best_available() -> Self {
        if ffmpeg_available() {
            Self::Mp4
        } else {
            Self::Gif
        }
    }

    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Mp4 => "mp4",
            Self::Gif => "gif",
        }
    }
}

/// Whether `ffmpeg -version` runs.
pub fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// An animated file being written, one frame at a time.
pub struct AnimationWriter {
    path: PathBuf,
    sink: Sink,
}

enum Sink {
    Gif {
        encoder: gif::Encoder<BufWriter<File>>,
        delay_cs: u16,
        indices: Vec<u8>,
        /// The last frame pushed (empty before the first).
        previous: Vec<u8>,
    },
    Ffmpeg {
        child: Child,
    },
}

impl AnimationWriter {
    /// Starts an animation of `width × height` frames at `fps` frames per second at `path`.
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Encode`] naming the file; [`RenderError::Ffmpeg`]
    /// if ffmpeg cannot be started; [`RenderError::Option`] for a GIF wider or taller than
    /// 65535 pixels or a frame rate outside 1–100.
    pub fn create(
        path: &Path,
        format: AnimationFormat,
        width: u32,
        height: u32,
        fps: u32,
    ) -> Result<Self, RenderError> {
        if !(1..=100).contains(&fps) {
            return Err(RenderError::Option {
                option: "fps",
                value: fps.to_string(),
                expected: "1 to 100 frames per second",
            });
        }
        let sink = match format {
            AnimationFormat::Gif => {
                let (w, h) = match (u16::try_from(width), u16::try_from(height)) {
                    (Ok(w), Ok(h)) => (w, h),
                    _ => {
                        return Err(RenderError::Option {
                            option: "size",
                            value: format!("{width}x{height}"),
                            expected: "at most 65535 pixels a side for a GIF",
                        });
                    }
                };
                let file = File::create(path).map_err(RenderError::io(path))?;
                let encode = |e: gif::EncodingError| RenderError::Encode {
                    path: path.to_path_buf(),
                    message: e.to_string(),
                };
                let mut encoder =
                    gif::Encoder::new(BufWriter::new(file), w, h, &palette()).map_err(encode)?;
                encoder.set_repeat(gif::Repeat::Infinite).map_err(encode)?;
                Sink::Gif {
                    encoder,
                    // GIF delays are in hundredths of a second.
                    delay_cs: (100 / fps).max(1) as u16,
                    indices: Vec::new(),
                    previous: Vec::new(),
                }
            }
            AnimationFormat::Mp4 => {
                let child = Command::new("ffmpeg")
                    .args([
                        "-y",
                        "-loglevel",
                        "error",
                        "-f",
                        "rawvideo",
                        "-pix_fmt",
                        "rgba",
                    ])
                    .args(["-s", &format!("{width}x{height}")])
                    .args(["-framerate", &fps.to_string(), "-i", "-"])
                    // yuv420p needs even sizes; the filter crops a pixel where needed.
                    .args(["-vf", "crop=trunc(iw/2)*2:trunc(ih/2)*2"])
                    .args(["-c:v", "libx264", "-preset", "veryfast", "-crf", "20"])
                    .args(["-pix_fmt", "yuv420p", "-movflags", "+faststart"])
                    .arg(path)
                    .stdin(Stdio::piped())
                    .spawn()
                    .map_err(|e| RenderError::Ffmpeg(format!("cannot start ffmpeg: {e}")))?;
                Sink::Ffmpeg { child }
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            sink,
        })
    }

    /// Appends `image` (of the size given to [`AnimationWriter::create`]).
    ///
    /// # Errors
    /// [`RenderError::Encode`] or [`RenderError::Ffmpeg`] naming the file.
    pub fn push(&mut self, image: &Image) -> Result<(), RenderError> {
        match &mut self.sink {
            Sink::Gif {
                encoder,
                delay_cs,
                indices,
                previous,
            } => {
                let whole = Rect {
                    left: 0,
                    top: 0,
                    width: image.width as usize,
                    height: image.height as usize,
                };
                let rect = if previous.len() == image.rgba.len() {
                    // An unchanged frame still takes its time on screen: one pixel is rewritten.
                    changed_rect(previous, &image.rgba, image.width as usize).unwrap_or(Rect {
                        width: 1,
                        height: 1,
                        ..whole
                    })
                } else {
                    whole
                };
                dither_to_palette(image, rect, indices);
                let mut frame = gif::Frame::from_indexed_pixels(
                    rect.width as u16,
                    rect.height as u16,
                    indices,
                    None,
                );
                frame.left = rect.left as u16;
                frame.top = rect.top as u16;
                frame.delay = *delay_cs;
                frame.dispose = gif::DisposalMethod::Keep;
                previous.clear();
                previous.extend_from_slice(&image.rgba);
                encoder
                    .write_frame(&frame)
                    .map_err(|e| RenderError::Encode {
                        path: self.path.clone(),
                        message: e.to_string(),
                    })
            }
            Sink::Ffmpeg { child } => child
                .stdin
                .as_mut()
                .ok_or_else(|| RenderError::Ffmpeg("ffmpeg's input is closed".into()))?
                .write_all(&image.rgba)
                .map_err(|e| RenderError::Ffmpeg(format!("writing a frame to ffmpeg: {e}"))),
        }
    }

    /// Finishes the file (for MP4, waits for ffmpeg).
    ///
    /// # Errors
    /// [`RenderError::Encode`] or [`RenderError::Ffmpeg`] naming the file.
    pub fn finish(self) -> Result<(), RenderError> {
        match self.sink {
            Sink::Gif { encoder, .. } => {
                let mut writer = encoder.into_inner().map_err(RenderError::io(&self.path))?;
                writer.flush().map_err(RenderError::io(&self.path))
            }
            Sink::Ffmpeg { mut child } => {
                drop(child.stdin.take());
                let status = child
                    .wait()
                    .map_err(|e| RenderError::Ffmpeg(format!("waiting for ffmpeg: {e}")))?;
                if status.success() {
                    Ok(())
                } else {
                    Err(RenderError::Ffmpeg(format!(
                        "ffmpeg failed ({status}) writing `{}`",
                        self.path.display()
                    )))
                }
            }
        }
    }
}

/// Levels of the fixed GIF palette: red, green, blue, then greys after the colour cube.
const LEVELS: [usize; 3] = [6, 7, 6];
const GREYS: usize = 4;

/// The fixed palette as RGB bytes: the 252 colours of the cube, then 4 light greys (the
/// background's neighbourhood, where banding shows most).
fn palette() -> Vec<u8> {
    let mut p = Vec::with_capacity(3 * 256);
    for r in 0..LEVELS[0] {
        for g in 0..LEVELS[1] {
            for b in 0..LEVELS[2] {
                for (v, n) in [(r, LEVELS[0]), (g, LEVELS[1]), (b, LEVELS[2])] {
                    p.push((v * 255 / (n - 1)) as u8);
                }
            }
        }
    }
    for k in 0..GREYS {
        let v = (232 + 6 * k) as u8;
        p.extend_from_slice(&[v, v, v]);
    }
    p
}

/// The 4×4 Bayer matrix, thresholds in sixteenths.
const BAYER: [[u8; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];

/// A rectangle of pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    left: usize,
    top: usize,
    width: usize,
    height: usize,
}

/// The smallest rectangle holding every pixel where the RGBA pictures `a` and `b` (rows of
/// `width` pixels) differ, or `None` if they are equal.
fn changed_rect(a: &[u8], b: &[u8], width: usize) -> Option<Rect> {
    let row = 4 * width;
    let rows_differ = |y: &usize| a[y * row..(y + 1) * row] != b[y * row..(y + 1) * row];
    let height = a.len() / row;
    let top = (0..height).find(rows_differ)?;
    let bottom = (0..height).rev().find(rows_differ)?;
    let (mut left, mut right) = (width, 0);
    for y in top..=bottom {
        let (ra, rb) = (&a[y * row..(y + 1) * row], &b[y * row..(y + 1) * row]);
        if let Some(x) = (0..left).find(|&x| ra[4 * x..4 * x + 4] != rb[4 * x..4 * x + 4]) {
            left = x;
        }
        if let Some(x) = (right..width)
            .rev()
            .find(|&x| ra[4 * x..4 * x + 4] != rb[4 * x..4 * x + 4])
        {
            right = x;
        }
    }
    let right = right.max(left);
    Some(Rect {
        left,
        top,
        width: right - left + 1,
        height: bottom - top + 1,
    })
}

/// Indices into [`palette`] for the pixels of `image` inside `rect`, row by row, with an
/// ordered dither on the colour cube (by the pixel's position in the whole picture, so a pixel
/// gets the same index whatever rectangle it is encoded in); pixels near the background's light
/// greys take the nearest grey undithered.
fn dither_to_palette(image: &Image, rect: Rect, out: &mut Vec<u8>) {
    out.clear();
    out.reserve(rect.width * rect.height);
    let w = image.width as usize;
    for y in rect.top..rect.top + rect.height {
        let row = &image.rgba[4 * (y * w + rect.left)..4 * (y * w + rect.left + rect.width)];
        for (i, px) in row.chunks_exact(4).enumerate() {
            let x = rect.left + i;
            out.push(palette_index(px, x, y));
        }
    }
}

/// The palette index of the pixel `px` (RGBA) at `(x, y)`.
fn palette_index(px: &[u8], x: usize, y: usize) -> u8 {
    let (r, g, b) = (px[0], px[1], px[2]);
    let (hi, lo) = (r.max(g).max(b), r.min(g).min(b));
    if lo >= 229 && hi <= 252 && hi - lo <= 4 {
        let k = ((usize::from(lo) + usize::from(hi)) / 2 - 229) / 6;
        return (LEVELS[0] * LEVELS[1] * LEVELS[2] + k.min(GREYS - 1)) as u8;
    }
    let t = u32::from(BAYER[y % 4][x % 4]) * 2 + 1; // (0..32) / 32 steps
    let q = |v: u8, n: usize| -> usize {
        let steps = (n - 1) as u32;
        // floor(v * steps / 255 + t / 32): on average over the 16 thresholds, v itself.
        ((u32::from(v) * steps * 32 + t * 255) / (255 * 32)).min(steps) as usize
    };
    let (ri, gi, bi) = (q(r, LEVELS[0]), q(g, LEVELS[1]), q(b, LEVELS[2]));
    ((ri * LEVELS[1] + gi) * LEVELS[2] + bi) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_palette_has_256_colours_and_exact_corners() {
        let p = palette();
        assert_eq!(p.len(), 3 * 256);
        assert_eq!(&p[..3], &[0, 0, 0]);
        let white = 3 * (LEVELS[0] * LEVELS[1] * LEVELS[2] - 1);
        assert_eq!(&p[white..white + 3], &[255, 255, 255]);
    }

    /// A flat colour dithers to palette entries whose mean is that colour within a level's
    /// sixteenth, and an exact palette colour maps onto itself.
    #[test]
    fn the_dither_keeps_the_mean_colour() {
        let p = palette();
        for colour in [
            [40u8, 90, 200],
            [200, 120, 30],
            [0, 0, 0],
            [255, 255, 255],
            [247, 247, 245],
        ] {
            let image = Image {
                width: 8,
                height: 8,
                rgba: (0..64)
                    .flat_map(|_| [colour[0], colour[1], colour[2], 255])
                    .collect(),
            };
            let mut idx = Vec::new();
            let whole = Rect {
                left: 0,
                top: 0,
                width: 8,
                height: 8,
            };
            dither_to_palette(&image, whole, &mut idx);
            for k in 0..3 {
                let mean: f64 = idx
                    .iter()
                    .map(|&i| f64::from(p[3 * i as usize + k]))
                    .sum::<f64>()
                    / 64.0;
                let step = 255.0 / (LEVELS[k] - 1) as f64;
                assert!(
                    (mean - f64::from(colour[k])).abs() <= step / 16.0 + 1.0,
                    "{colour:?} channel {k}: mean {mean}"
                );
            }
        }
    }

    #[test]
    fn the_changed_rectangle_holds_every_difference_and_no_more() {
        let (w, h) = (7usize, 5usize);
        let a = vec![200u8; 4 * w * h];
        assert_eq!(changed_rect(&a, &a, w), None);
        let mut b = a.clone();
        for (x, y) in [(2, 1), (5, 3), (3, 2)] {
            b[4 * (y * w + x) + 1] = 0;
        }
        let r = changed_rect(&a, &b, w).unwrap();
        assert_eq!(
            r,
            Rect {
                left: 2,
                top: 1,
                width: 4,
                height: 3
            }
        );
    }

    /// A GIF written frame by frame decodes back to the pictures' palette colours: each
    /// stored rectangle drawn over the last gives every frame whole.
    #[test]
    fn a_gif_of_changed_rectangles_decodes_to_every_frame() {
        let (w, h) = (12u32, 9u32);
        let frames: Vec<Image> = (0..4)
            .map(|f| Image {
                width: w,
                height: h,
                rgba: (0..w * h)
                    .flat_map(|i| {
                        let (x, y) = (i % w, i / w);
                        let on = x == 2 + 2 * f && (3..6).contains(&y);
                        if on {
                            [200, 30, 30, 255]
                        } else {
                            [247, 247, 245, 255]
                        }
                    })
                    .collect(),
            })
            .collect();
        let path = std::env::temp_dir().join(format!("cosserat-render-{}.gif", std::process::id()));
        let mut writer = AnimationWriter::create(&path, AnimationFormat::Gif, w, h, 10).unwrap();
        for f in &frames {
            writer.push(f).unwrap();
        }
        writer.finish().unwrap();
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(File::open(&path).unwrap()).unwrap();
        let p = palette();
        let mut canvas = vec![0u8; (4 * w * h) as usize];
        for (k, f) in frames.iter().enumerate() {
            let frame = decoder.read_next_frame().unwrap().expect("a frame");
            if k > 0 {
                assert!(frame.width < w as u16, "frame {k} is stored whole");
            }
            for y in 0..frame.height as usize {
                for x in 0..frame.width as usize {
                    let (cx, cy) = (frame.left as usize + x, frame.top as usize + y);
                    let src = 4 * (y * frame.width as usize + x);
                    let dst = 4 * (cy * w as usize + cx);
                    canvas[dst..dst + 4].copy_from_slice(&frame.buffer[src..src + 4]);
                }
            }
            for (i, px) in f.rgba.chunks(4).enumerate() {
                let (x, y) = (i % w as usize, i / w as usize);
                let c = 3 * palette_index(px, x, y) as usize;
                assert_eq!(
                    &canvas[4 * i..4 * i + 3],
                    &p[c..c + 3],
                    "frame {k} pixel ({x}, {y})"
                );
            }
        }
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn png_round_trips() {
        let image = Image {
            width: 3,
            height: 2,
            rgba: (0..24).map(|i| (i * 10) as u8).collect(),
        };
        let path = std::env::temp_dir().join(format!("cosserat-render-{}.png", std::process::id()));
        write_png(&path, &image).unwrap();
        let back = read_png(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(back, image);
    }
}
