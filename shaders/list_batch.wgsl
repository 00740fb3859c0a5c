// The bindings of a pass over a batch of neighbour lists (cluster_unions.wgsl,
// spray_components.wgsl), after its uniform block at 0.

// Where each point's list begins among all lists (one more at the end).
@group(0) @binding(1) var<storage, read> list_start: array<u32>;
// The batch's lists, from slot `list_base` among all lists, their marks in the high bits
// (LINK_BIT, FAR_BIT; ID_MASK keeps the index).
@group(0) @binding(2) var<storage, read> lists: array<u32>;
