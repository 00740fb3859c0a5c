// The union of the neighbour lists of each cluster of consecutive points
// (crates/gpubake/src/unions.rs), as slosh_mls::cluster_lists makes it: each id once, in index
// order. A workgroup takes one cluster: it sets its members' ids in a bitset in workgroup
// memory, over their span, or (where they span more) its halves over the ids nearest the
// lowest and those nearest the highest, and reads the set bits out in order, so the lists
// need not be read back to be merged. Dispatched twice: first to count the ids each union
// holds (SPAN_WIDE where an id falls outside the bitset: the host merges that cluster), then
// to write them where the counts' prefix sum says. Follows list_batch.wgsl; ID_MASK,
// SPAN_WORDS and SPAN_WIDE come from crates/gpubake/src/layout.rs.

struct UnionParams {
    // The dispatch's first cluster, and how many it takes.
    first_cluster: u32,
    clusters: u32,
    // Points in the set, and points per cluster.
    points: u32,
    size: u32,
    // The slot among all lists of `lists`' first word.
    list_base: u32,
    // Workgroups per row of the dispatch.
    row_groups: u32,
    // 0: count the unions; 1: write them.
    write: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: UnionParams;
// Per cluster of the dispatch: its union's length, or SPAN_WIDE.
@group(0) @binding(3) var<storage, read_write> counts: array<u32>;
// Per cluster of the dispatch: where its union begins in `unions` (`write_unions`).
@group(0) @binding(4) var<storage, read> union_start: array<u32>;
@group(0) @binding(5) var<storage, read_write> unions: array<u32>;

const THREADS: u32 = 64u;
const EMPTY: u32 = 0xffffffffu;
// Words of each half of a split bitset.
const HALF: u32 = SPAN_WORDS / 2u;

var<workgroup> bits: array<atomic<u32>, SPAN_WORDS>;
var<workgroup> lowest: atomic<u32>;
var<workgroup> highest: atomic<u32>;
// Set where an id falls between the halves of a split bitset.
var<workgroup> stray: atomic<u32>;
// Set bits in each thread's share of the words (consecutive words, thread by thread).
var<workgroup> thread_counts: array<u32, THREADS>;

// Where a cluster's ids span more words than the bitset has (a cluster beside a boundary of
// the Morton order: some of its neighbours lie far along the order), its halves take the ids
// nearest the lowest and those nearest the highest, which are often all of them.
struct Span {
    // The id of bit 0 of word 0, and (split) of word HALF.
    base: u32,
    high_base: u32,
    // The words in use (0: no ids).
    words: u32,
    split: bool,
    wide: bool,
}

// The bit of `id` in the bitset, or EMPTY where it falls between the halves.
fn bit_of(span: Span, id: u32) -> u32 {
    if !span.split || id < span.base + HALF * 32u {
        return id - span.base;
    }
    if id >= span.high_base {
        return HALF * 32u + (id - span.high_base);
    }
    return EMPTY;
}

// The id of bit 0 of word `w`.
fn word_base(span: Span, w: u32) -> u32 {
    if span.split && w >= HALF {
        return span.high_base + (w - HALF) * 32u;
    }
    return span.base + w * 32u;
}

// The cluster's ids set in `bits`, each thread's count of them in `thread_counts`.
fn set_bits(cluster: u32, thread: u32) -> Span {
    for (var w = thread; w < SPAN_WORDS; w += THREADS) {
        atomicStore(&bits[w], 0u);
    }
    if thread == 0u {
        atomicStore(&lowest, EMPTY);
        atomicStore(&highest, 0u);
        atomicStore(&stray, 0u);
    }
    workgroupBarrier();
    let first_point = min(cluster * params.size, params.points);
    let last_point = min(first_point + params.size, params.points);
    let a = list_start[first_point] - params.list_base;
    let b = list_start[last_point] - params.list_base;
    for (var k = a + thread; k < b; k += THREADS) {
        let id = lists[k] & ID_MASK;
        atomicMin(&lowest, id);
        atomicMax(&highest, id);
    }
    workgroupBarrier();
    let lo = atomicLoad(&lowest);
    let hi = atomicLoad(&highest);
    var span = Span(0u, 0u, 0u, false, false);
    if lo <= hi {
        span.base = lo & ~31u;
        let words = (hi - span.base) / 32u + 1u;
        span.split = words > SPAN_WORDS;
        span.words = min(words, SPAN_WORDS);
        if span.split {
            span.high_base = (hi & ~31u) - (HALF - 1u) * 32u;
        }
    }
    for (var k = a + thread; k < b; k += THREADS) {
        let at = bit_of(span, lists[k] & ID_MASK);
        if at == EMPTY {
            atomicStore(&stray, 1u);
        } else {
            atomicOr(&bits[at / 32u], 1u << (at % 32u));
        }
    }
    workgroupBarrier();
    span.wide = atomicLoad(&stray) != 0u;
    var count = 0u;
    if !span.wide {
        let share = share_of(span, thread);
        for (var w = share.x; w < share.y; w++) {
            count += countOneBits(atomicLoad(&bits[w]));
        }
    }
    thread_counts[thread] = count;
    workgroupBarrier();
    return span;
}

// The words [x, y) of the span that `thread` reads.
fn share_of(span: Span, thread: u32) -> vec2<u32> {
    let per = (span.words + THREADS - 1u) / THREADS;
    return vec2<u32>(min(thread * per, span.words), min((thread + 1u) * per, span.words));
}

@compute @workgroup_size(64)
fn cluster_unions(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let k = group.x + group.y * params.row_groups;
    if k >= params.clusters {
        return;
    }
    let span = set_bits(params.first_cluster + k, thread);
    if params.write == 0u {
        if thread == 0u {
            var total = 0u;
            for (var t = 0u; t < THREADS; t++) {
                total += thread_counts[t];
            }
            counts[k] = select(total, SPAN_WIDE, span.wide);
        }
        return;
    }
    if span.wide {
        return;
    }
    var at = union_start[k];
    for (var t = 0u; t < thread; t++) {
        at += thread_counts[t];
    }
    let share = share_of(span, thread);
    for (var w = share.x; w < share.y; w++) {
        var word = atomicLoad(&bits[w]);
        while word != 0u {
            unions[at] = word_base(span, w) + countTrailingZeros(word);
            at++;
            word &= word - 1u;
        }
    }
}
