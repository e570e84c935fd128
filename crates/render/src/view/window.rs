//! The interactive viewer: a winit window over the same frame loop as the headless mode
//! ([`Viewer::frame`]: stream, cut, draw offscreen), whose picture is copied into the window's
//! surface each redraw. Thin on purpose: it cannot be tested on a machine without a display,
//! so everything it does besides input and presenting is the tested headless path.
//!
//! Camera: an orbit around a target in the model's bounding cube (coordinates as in
//! [`super::FlyPath`]). Left drag or A/D, Q/E orbit; the wheel or W/S move in and out (a fly-in
//! towards the target); arrow keys move the target across the view; R resets; `[` and `]`
//! halve and double the pixel error; Esc quits.

use std::sync::Arc;

use glam::DVec3;
use voxlod_format::Reader;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use super::path::{cube, cube_shot};
use super::{StreamConfig, Viewer};
use crate::draw::gpu_error;
use crate::{RenderError, Renderer};

/// Orbit camera state in cube coordinates.
#[derive(Clone, Copy, Debug)]
struct Orbit {
    yaw: f64,
    pitch: f64,
    distance: f64,
    target: DVec3,
}

impl Default for Orbit {
    fn default() -> Self {
        Orbit {
            yaw: 0.4,
            pitch: 0.25,
            distance: 3.5,
            target: DVec3::ZERO,
        }
    }
}

impl Orbit {
    fn eye(&self) -> DVec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + DVec3::new(sy * cp, sp, cy * cp) * self.distance
    }
}

struct Open<'a> {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    format: wgpu::TextureFormat,
    viewer: Viewer<'a>,
}

struct App<'a> {
    reader: &'a Reader,
    config: StreamConfig,
    two_sided: bool,
    size: (u32, u32),
    orbit: Orbit,
    drag: Option<(f64, f64)>,
    cursor: (f64, f64),
    open: Option<Open<'a>>,
    error: Option<RenderError>,
}

/// What to do instead of a window, said with every failure to open one.
const NO_WINDOW_HINT: &str = "render a camera path headless instead (voxlod view FILE --fly \
     configs/fly-in.json --frames DIR, or voxlod render FILE -o PICTURE.png), or give the window \
     a virtual display (xvfb-run voxlod view FILE)";

/// Why no window can open here, before winit is asked: on Linux and the BSDs a window needs
/// an X11 or Wayland display named by the environment.
pub fn no_display() -> Option<String> {
    if cfg!(any(
        target_os = "macos",
        target_os = "windows",
        target_os = "ios",
        target_os = "android"
    )) {
        return None;
    }
    let set = |k: &str| std::env::var_os(k).is_some_and(|v| !v.is_empty());
    if set("DISPLAY") || set("WAYLAND_DISPLAY") || set("WAYLAND_SOCKET") {
        return None;
    }
    Some(format!(
        "no display to open a window on (neither DISPLAY nor WAYLAND_DISPLAY is set): {NO_WINDOW_HINT}"
    ))
}

/// Opens a window on `reader` and runs until it is closed.
pub fn run(
    reader: &Reader,
    config: StreamConfig,
    size: (u32, u32),
    two_sided: bool,
) -> Result<(), RenderError> {
    if let Some(why) = no_display() {
        return Err(RenderError::Option(why));
    }
    // winit's own message names a source file of its crate; the hint says what to do
    let event_loop = EventLoop::new().map_err(|e| {
        RenderError::Option(format!("cannot open a window ({e}): {NO_WINDOW_HINT}"))
    })?;
    let mut app = App {
        reader,
        config,
        two_sided,
        size,
        orbit: Orbit::default(),
        drag: None,
        cursor: (0.0, 0.0),
        open: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| RenderError::Option(format!("window: {e}")))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

impl<'a> App<'a> {
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<Open<'a>, RenderError> {
        let attrs = Window::default_attributes()
            .with_title(format!("voxlod view {}", self.reader.path().display()))
            .with_inner_size(winit::dpi::PhysicalSize::new(self.size.0, self.size.1));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| RenderError::Option(format!("cannot open a window: {e}")))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| RenderError::Option(format!("cannot draw into the window: {e}")))?;
        let gpu = voxlod_gpu::open_device_for_surface(
            &instance,
            &surface,
            "voxlod-view",
            wgpu::Features::empty(),
        )
        .map_err(gpu_error)?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // the picture is final 8-bit RGBA: a plain (not sRGB) 8-bit format takes it as is
        let format = [
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureFormat::Bgra8Unorm,
        ]
        .into_iter()
        .find(|f| caps.formats.contains(f))
        .ok_or_else(|| {
            RenderError::Option(format!(
                "the window offers no plain 8-bit format ({:?})",
                caps.formats
            ))
        })?;
        if !caps.usages.contains(wgpu::TextureUsages::COPY_DST) {
            return Err(RenderError::Option(
                "the window's surface cannot be copied into".into(),
            ));
        }
        let mut renderer = Renderer::with_gpu(gpu)?;
        renderer.set_two_sided(self.two_sided);
        let viewer = Viewer::new(self.reader, renderer, self.config)?;
        let open = Open {
            window,
            surface,
            format,
            viewer,
        };
        configure(&open, self.size);
        Ok(open)
    }

    fn redraw(&mut self) -> Result<(), RenderError> {
        let Some(open) = &mut self.open else {
            return Ok(());
        };
        let (w, h) = self.size;
        if w == 0 || h == 0 {
            return Ok(());
        }
        let (centre, half) = cube(open.viewer.bounds());
        let shot = cube_shot(
            centre + self.orbit.eye() * half,
            centre + self.orbit.target * half,
            DVec3::Y,
            45f64.to_radians(),
            half,
            (w, h),
        );
        let frame = open.viewer.frame(&shot)?;
        let texture = match open.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            _ => {
                configure(open, self.size);
                open.window.request_redraw();
                return Ok(());
            }
        };
        let mut rgba = frame.picture.rgba;
        if open.format == wgpu::TextureFormat::Bgra8Unorm {
            rgba.chunks_exact_mut(4).for_each(|p| p.swap(0, 2));
        }
        let queue = open.viewer.renderer().queue();
        queue.write_texture(
            texture.texture.as_image_copy(),
            &rgba,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        queue.submit([]);
        queue.present(texture);
        open.window.set_title(&format!(
            "voxlod view: {} nodes drawn ({} occluded), {} resident ({:.1} MiB), {} pending, error {} px",
            frame.stats.drawn_nodes,
            frame.stats.occluded_nodes,
            frame.stats.nodes_resident,
            frame.stats.bytes_resident as f64 / 1048576.0,
            frame.stats.pending,
            self.config.max_error_px
        ));
        // keep streaming while requests wait
        if frame.stats.pending > 0 {
            open.window.request_redraw();
        }
        Ok(())
    }

    fn key(&mut self, key: &Key, event_loop: &ActiveEventLoop) {
        let o = &mut self.orbit;
        let step = 0.08;
        let fwd = (o.target - o.eye()).normalize();
        let right = fwd.cross(DVec3::Y).normalize_or_zero();
        let up = right.cross(fwd);
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::ArrowLeft) => o.target -= right * step * o.distance,
            Key::Named(NamedKey::ArrowRight) => o.target += right * step * o.distance,
            Key::Named(NamedKey::ArrowUp) => o.target += up * step * o.distance,
            Key::Named(NamedKey::ArrowDown) => o.target -= up * step * o.distance,
            Key::Character(c) => match c.as_str() {
                "a" | "A" => o.yaw -= step,
                "d" | "D" => o.yaw += step,
                "q" | "Q" => o.pitch = (o.pitch + step).min(1.5),
                "e" | "E" => o.pitch = (o.pitch - step).max(-1.5),
                "w" | "W" => o.distance = (o.distance * 0.9).max(0.01),
                "s" | "S" => o.distance = (o.distance / 0.9).min(100.0),
                "r" | "R" => *o = Orbit::default(),
                "[" => self.config.max_error_px = (self.config.max_error_px / 2.0).max(0.25),
                "]" => self.config.max_error_px = (self.config.max_error_px * 2.0).min(64.0),
                _ => return,
            },
            _ => return,
        }
        if let Some(open) = &mut self.open {
            open.viewer.set_max_error(self.config.max_error_px);
            open.window.request_redraw();
        }
    }
}

fn configure(open: &Open, (w, h): (u32, u32)) {
    if w == 0 || h == 0 {
        return;
    }
    open.surface.configure(
        &open.viewer.renderer().gpu().device,
        &wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::COPY_DST,
            format: open.format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: w,
            height: h,
            desired_maximum_frame_latency: 2,
            present_mode: wgpu::PresentMode::Fifo,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: vec![],
        },
    );
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.open.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(open) => {
                open.window.request_redraw();
                self.open = Some(open);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(s) => {
                self.size = (s.width, s.height);
                if let Some(open) = &self.open {
                    configure(open, self.size);
                    open.window.request_redraw();
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw() {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
            WindowEvent::KeyboardInput {
                event:
                    KeyEvent {
                        logical_key,
                        state: ElementState::Pressed,
                        ..
                    },
                ..
            } => self.key(&logical_key, event_loop),
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.drag = (state == ElementState::Pressed).then_some(self.cursor);
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                if let Some((x0, y0)) = self.drag {
                    self.orbit.yaw -= (position.x - x0) * 0.01;
                    self.orbit.pitch =
                        (self.orbit.pitch + (position.y - y0) * 0.01).clamp(-1.5, 1.5);
                    self.drag = Some(self.cursor);
                    if let Some(open) = &self.open {
                        open.window.request_redraw();
                    }
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.orbit.distance = (self.orbit.distance * 0.9f64.powf(lines)).clamp(0.01, 100.0);
                if let Some(open) = &self.open {
                    open.window.request_redraw();
                }
            }
            _ => {}
        }
    }
}
