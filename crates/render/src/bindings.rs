//! Bind group layout entries and bind group entries, as every compute pass here declares them:
//! each storage array bound in `RANGES` consecutive slices of its buffer (shaders.rs), and one
//! uniform block.

use crate::shaders::{RANGES, RangedArray, UNIFORM_BINDING, elements_per_range};

/// A compute-visible buffer binding of `ty` at `binding`.
fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The layout of `arrays` (all in one group), plus the uniform block if `uniform`.
pub(crate) fn layout_entries(
    arrays: &[RangedArray],
    uniform: bool,
) -> Vec<wgpu::BindGroupLayoutEntry> {
    let mut entries: Vec<_> = arrays
        .iter()
        .flat_map(|a| {
            let ty = wgpu::BufferBindingType::Storage {
                read_only: !a.writable,
            };
            (0..RANGES).map(move |r| buffer_entry(a.slot * RANGES + r, ty))
        })
        .collect();
    if uniform {
        entries.push(buffer_entry(
            UNIFORM_BINDING,
            wgpu::BufferBindingType::Uniform,
        ));
    }
    entries
}

/// Byte ranges of `array`'s bindings over a buffer of `size` bytes under a binding limit of
/// `limit`: consecutive slices of `elements_per_range` elements; a range past the end binds
/// the first slice again (the shader never reads it).
pub(crate) fn ranges(array: &RangedArray, size: u64, limit: u64) -> Vec<(u64, u64)> {
    let span = elements_per_range(limit, array.element_size) * array.element_size;
    (0..u64::from(RANGES))
        .map(|r| {
            let offset = r * span;
            if offset < size {
                (offset, span.min(size - offset))
            } else {
                (0, span.min(size))
            }
        })
        .collect()
}

/// Ranges an array of `size` bytes needs under `limit` (at least 1).
fn ranges_needed(array: &RangedArray, size: u64, limit: u64) -> u64 {
    let span = elements_per_range(limit, array.element_size) * array.element_size;
    size.div_ceil(span).max(1)
}

/// The most bytes an array can hold and still be bound: `RANGES` bindings under `limit`,
/// within the device's largest buffer.
pub(crate) fn capacity(device: &wgpu::Device, limit: u64, array: &RangedArray) -> u64 {
    let span = elements_per_range(limit, array.element_size) * array.element_size;
    (u64::from(RANGES) * span).min(device.limits().max_buffer_size)
}

/// Whether `what`, an array of `bytes`, spans more than one binding under `limit`; why it
/// cannot be bound where it needs more than `RANGES` or exceeds the device's largest buffer
/// (`adapter` names the device in that message).
pub(crate) fn needs_split(
    device: &wgpu::Device,
    adapter: &str,
    limit: u64,
    array: &RangedArray,
    what: &str,
    bytes: u64,
) -> Result<bool, String> {
    let needed = ranges_needed(array, bytes, limit);
    let max_buffer = device.limits().max_buffer_size;
    if needed > u64::from(RANGES) || bytes > max_buffer {
        return Err(format!(
            "'{what}' takes {bytes} bytes on the GPU; {} binds at most {RANGES} ranges of {} bytes per array, in buffers of at most {max_buffer} bytes",
            adapter,
            elements_per_range(limit, array.element_size) * array.element_size
        ));
    }
    Ok(needed > 1)
}

/// Entries binding `buffers` (one per array, in `arrays`' order) and the uniform block.
pub(crate) fn bind_entries<'a>(
    arrays: &[RangedArray],
    buffers: &[&'a wgpu::Buffer],
    uniform: Option<&'a wgpu::Buffer>,
    limit: u64,
) -> Vec<wgpu::BindGroupEntry<'a>> {
    let mut entries: Vec<_> = arrays
        .iter()
        .zip(buffers)
        .flat_map(|(a, buffer)| {
            ranges(a, buffer.size(), limit)
                .into_iter()
                .zip(0..)
                .map(move |((offset, size), r)| wgpu::BindGroupEntry {
                    binding: a.slot * RANGES + r,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer,
                        offset,
                        size: wgpu::BufferSize::new(size),
                    }),
                })
        })
        .collect();
    if let Some(uniform) = uniform {
        entries.push(wgpu::BindGroupEntry {
            binding: UNIFORM_BINDING,
            resource: uniform.as_entire_binding(),
        });
    }
    entries
}
