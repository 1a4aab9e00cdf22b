//! Opening a device without a window (headless), for `voyage bench render`, tests and
//! batch rendering.
//!
//! CI machines and many workstations have no GPU: Mesa's lavapipe (a CPU Vulkan driver) is
//! then the adapter, and it reports itself as a CPU device. We therefore ask for Vulkan first
//! (hardware or lavapipe) and GL only as a fallback, and never reject an adapter for being a
//! CPU: a slow image beats none, and the tests must run there.

use crate::error::RenderError;

/// The largest image side we ask for. The endoscopic view is at most a few thousand pixels
/// wide; asking for more than needed could refuse adapters for nothing.
const WANTED_TEXTURE_SIDE: u32 = 8192;

/// An instance, adapter, device and queue opened without a surface.
///
/// Vulkan is tried alone first, and GL only when Vulkan finds nothing: starting the GL
/// backend probes EGL platforms (and complains about a missing Wayland session on stderr)
/// even when a Vulkan adapter would be chosen anyway. `WGPU_BACKEND` (e.g. `gl`) overrides.
pub(crate) fn open_headless() -> Result<(wgpu::Device, wgpu::Queue), RenderError> {
    let tries = match wgpu::Backends::from_env() {
        Some(backends) => vec![backends],
        None => vec![wgpu::Backends::VULKAN, wgpu::Backends::GL],
    };
    let mut failures = Vec::new();
    let mut found = None;
    for backends in tries {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle().with_env();
        desc.backends = backends;
        let instance = wgpu::Instance::new(desc);
        match pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        })) {
            Ok(adapter) => {
                found = Some(adapter);
                break;
            }
            Err(e) => failures.push(format!("{backends:?}: {e}")),
        }
    }
    let adapter = found.ok_or_else(|| RenderError::NoAdapter(failures.join("; ")))?;

    let info = adapter.get_info();
    let required_limits = limits_for(&adapter.limits());
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("voyage headless"),
        required_features: wgpu::Features::empty(),
        required_limits,
        ..Default::default()
    }))
    .map_err(|e| RenderError::NoDevice {
        adapter: format!("{} ({:?})", info.name, info.backend),
        reason: e.to_string(),
    })?;
    Ok((device, queue))
}

/// The limits we request: WebGPU's defaults where the adapter meets them (GL adapters may
/// not, hence the downlevel defaults then), raised only where our meshes and images need it.
///
/// Meshes: 1.5 M triangles make an 18 MB index buffer and ~0.8 M vertices a 19 MB vertex
/// buffer, well under the default `max_buffer_size` of 256 MB; the buffers are never bound as
/// storage, so `max_storage_buffer_binding_size` does not matter. We still take the
/// adapter's whole `max_buffer_size` so that a larger mesh fails only where the hardware
/// really cannot hold it. Images: the default 8192-pixel side, or the adapter's up to that.
fn limits_for(adapter: &wgpu::Limits) -> wgpu::Limits {
    let defaults = wgpu::Limits::default();
    let mut limits = if defaults.check_limits(adapter) {
        defaults
    } else {
        wgpu::Limits::downlevel_defaults().using_resolution(adapter.clone())
    };
    limits.max_texture_dimension_2d = limits
        .max_texture_dimension_2d
        .max(adapter.max_texture_dimension_2d.min(WANTED_TEXTURE_SIDE));
    limits.max_buffer_size = limits.max_buffer_size.max(adapter.max_buffer_size);
    limits
}

/// One line naming the adapter behind a device: name, backend, device type, driver.
pub(crate) fn summary(device: &wgpu::Device) -> String {
    let info = device.adapter_info();
    let driver = match (info.driver.is_empty(), info.driver_info.is_empty()) {
        (true, true) => "unknown driver".to_string(),
        (false, true) => info.driver.clone(),
        (true, false) => info.driver_info.clone(),
        (false, false) => format!("{} {}", info.driver, info.driver_info),
    };
    format!(
        "{} ({:?}, {:?}, {})",
        info.name, info.backend, info.device_type, driver
    )
}
