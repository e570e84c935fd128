//! The picture's render pass, shared by its two pipelines (the voxel faces' in
//! [`crate::draw`], the source triangles' in [`crate::source_draw`]): the target formats, the
//! pipeline both are built with, and the offscreen targets they draw into.

/// The resolved picture's format.
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// The depth buffer's format.
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Samples per pixel (4× multisampling).
const SAMPLES: u32 = 4;

/// A pipeline of the picture's pass (the voxel faces', the source triangles'): `module`'s `vs`
/// and `fs` entries over one vertex buffer with `layout`'s uniforms, depth tested (less) and
/// written, into the pass's targets ([`COLOR_FORMAT`], [`DEPTH_FORMAT`], [`SAMPLES`]). A
/// `probe` pipeline (occlusion culling's test of a hidden node) is depth tested the same way
/// but writes neither colour nor depth.
pub(crate) fn pass_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    buffer: wgpu::VertexBufferLayout,
    primitive: wgpu::PrimitiveState,
    probe: bool,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(buffer)],
        },
        primitive,
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(!probe),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: SAMPLES,
            ..Default::default()
        },
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: COLOR_FORMAT,
                blend: None,
                write_mask: if probe {
                    wgpu::ColorWrites::empty()
                } else {
                    wgpu::ColorWrites::ALL
                },
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The offscreen targets of one picture: the multisampled colour and depth attachments and
/// the resolved colour texture that is read back.
pub(crate) struct Targets {
    pub size: wgpu::Extent3d,
    pub resolved: wgpu::Texture,
    pub msaa_view: wgpu::TextureView,
    pub resolved_view: wgpu::TextureView,
    pub depth_view: wgpu::TextureView,
}

impl Targets {
    /// The targets of a `w`×`h` picture.
    pub(crate) fn new(device: &wgpu::Device, w: u32, h: u32) -> Targets {
        let size = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let texture = |format, samples, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: None,
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let msaa = texture(
            COLOR_FORMAT,
            SAMPLES,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let resolved = texture(
            COLOR_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = texture(
            DEPTH_FORMAT,
            SAMPLES,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        Targets {
            size,
            msaa_view: msaa.create_view(&Default::default()),
            resolved_view: resolved.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            resolved,
        }
    }
}
