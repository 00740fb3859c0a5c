//! WGSL checked by naga: a module validated, and the layout of its structs, which the
//! `#[repr(C)]` Pod mirrors on the Rust side must match ([`check_layout!`](crate::check_layout)).

/// Validates with the one capability the passes need beyond the baseline: `unpack2x16float`
/// (the balls' half floats), which `Gpu::from_parts` requires of the adapter.
pub fn validate(name: &str, source: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
    if let Err(e) = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32,
    )
    .validate(&module)
    {
        panic!("{name}: {}", e.emit_to_string(source));
    }
    module
}

/// (name, offset) of each member of the WGSL struct `name`, and the struct's size.
pub fn layout(module: &naga::Module, name: &str) -> (Vec<(String, u32)>, u32) {
    let ty = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no struct {name}"))
        .1;
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("{name} is not a struct")
    };
    (
        members
            .iter()
            .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
            .collect(),
        *span,
    )
}

/// Asserts that the WGSL struct `$wgsl` of `$module` has `$rust`'s size and its fields, in
/// order, at `$rust`'s offsets.
#[macro_export]
macro_rules! check_layout {
    ($module:expr, $wgsl:literal, $rust:ty, [$($field:ident),*]) => {{
        let (members, span) = $crate::wgsl::layout($module, $wgsl);
        assert_eq!(span as usize, size_of::<$rust>(), "size of {}", $wgsl);
        let rust: Vec<(String, u32)> =
            vec![$((stringify!($field).to_string(), std::mem::offset_of!($rust, $field) as u32)),*];
        assert_eq!(members, rust, "member offsets of {}", $wgsl);
    }};
}
