//! Element types: how many nodes each has, so that parts of any type can be read past.

/// Nodes per element of a fixed-size EnSight element type (`g_` ghost variants included);
/// `None` for the variable-size Gold types (`nsided`, `nfaced`) and for unknown words.
pub fn nodes_per_element(kind: &str) -> Option<usize> {
    let base = kind.strip_prefix("g_").unwrap_or(kind);
    Some(match base {
        "point" => 1,
        "bar2" => 2,
        "bar3" => 3,
        "tria3" => 3,
        "tria6" => 6,
        "quad4" => 4,
        "quad8" => 8,
        "tetra4" => 4,
        "tetra10" => 10,
        "pyramid5" => 5,
        "pyramid13" => 13,
        "penta6" => 6,
        "penta15" => 15,
        "hexa8" => 8,
        "hexa20" => 20,
        _ => return None,
    })
}

/// True for the words that start an element block (fixed-size or Gold's polygons/polyhedra).
pub fn is_element_keyword(kind: &str) -> bool {
    nodes_per_element(kind).is_some()
        || matches!(kind.strip_prefix("g_").unwrap_or(kind), "nsided" | "nfaced")
}
