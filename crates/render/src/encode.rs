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
//! and is deterministic.

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
            } => {
                dither_to_palette(image, indices);
                let mut frame = gif::Frame::from_indexed_pixels(
                    image.width as u16,
                    image.height as u16,
                    indices,
                    None,
                );
                frame.delay = *delay_cs;
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

/// Indices into [`palette`] for `image`, with an ordered dither on the colour cube; pixels
/// near the background's light greys take the nearest grey undithered.
fn dither_to_palette(image: &Image, out: &mut Vec<u8>) {
    out.clear();
    out.reserve((image.width * image.height) as usize);
    let w = image.width as usize;
    for (i, px) in image.rgba.chunks_exact(4).enumerate() {
        let (x, y) = (i % w, i / w);
        let (r, g, b) = (px[0], px[1], px[2]);
        let (hi, lo) = (r.max(g).max(b), r.min(g).min(b));
        if lo >= 229 && hi <= 252 && hi - lo <= 4 {
            let k = ((usize::from(lo) + usize::from(hi)) / 2 - 229) / 6;
            out.push((LEVELS[0] * LEVELS[1] * LEVELS[2] + k.min(GREYS - 1)) as u8);
            continue;
        }
        let t = u32::from(BAYER[y % 4][x % 4]) * 2 + 1; // (0..32) / 32 steps
        let q = |v: u8, n: usize| -> usize {
            let steps = (n - 1) as u32;
            // floor(v * steps / 255 + t / 32): on average over the 16 thresholds, v itself.
            ((u32::from(v) * steps * 32 + t * 255) / (255 * 32)).min(steps) as usize
        };
        let (ri, gi, bi) = (q(r, LEVELS[0]), q(g, LEVELS[1]), q(b, LEVELS[2]));
        out.push(((ri * LEVELS[1] + gi) * LEVELS[2] + bi) as u8);
    }
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
            dither_to_palette(&image, &mut idx);
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
