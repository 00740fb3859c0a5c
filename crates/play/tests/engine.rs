#![allow(clippy::unwrap_used)]
//! The engine on a real Vulkan adapter (lavapipe in CI) over a baked series: streaming under a
//! tiny budget, stand-ins, the whole series resident when it fits, progressive refinement
//! against a direct render, failures, and a series that grows while a bake runs.

use std::path::Path;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use slosh_bake::{BakeParams, NormalSource, SurfaceSelect, bake_step};
use slosh_cache::{Manifest, step_file_name, write_step};
use slosh_mls::Camera;
use slosh_play::export::{ExportJob, ExportRequest, ExportState, frame_path, trace_file};
use slosh_play::{Draw, Engine, EngineOptions, FrameReport, FrameRequest, Pace, Quality};
use slosh_render::{Frame, Gpu, GpuStep, HostStep, TraceParams, Tracer};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

fn gpu() -> Option<Arc<Gpu>> {
    static GPU: OnceLock<Option<Arc<Gpu>>> = OnceLock::new();
    GPU.get_or_init(|| {
        slosh_testkit::gpu_or_skip(Gpu::new(slosh_testkit::adapter().as_deref())).map(Arc::new)
    })
    .clone()
}

/// Steps `steps` of a moving 1500-point sphere baked into `dir`, and the manifest.
fn bake_series(dir: &Path, steps: std::ops::Range<usize>, manifest: bool) {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 1500, 3)).unwrap();
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    for step in steps {
        let input = slosh_testkit::scene_step(&scene, step, "sphere");
        let baked = bake_step(&input, &params).unwrap();
        let path = dir.join(step_file_name(step));
        write_step(&path, baked.header, &baked.sections, params.compression).unwrap();
    }
    if manifest {
        let (m, failed) = Manifest::rebuild(dir).unwrap();
        assert!(failed.is_empty());
        m.write(dir).unwrap();
    }
}

fn camera() -> Camera {
    Camera {
        eye: [0.5, -4.0, 1.5],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov_y: 45.0,
        width: 64,
        height: 48,
    }
}

fn request(iterations: u32) -> FrameRequest {
    FrameRequest {
        seconds: 0.0,
        camera: camera(),
        params: TraceParams {
            iterations,
            ..TraceParams::default()
        },
        camera_moving: false,
        frame_budget_ms: None,
    }
}

fn frame(engine: &mut Engine, request: &FrameRequest) -> FrameReport {
    engine.frame_and_wait(request).unwrap()
}

/// Frames until `position` is shown; the reports on the way.
fn show(engine: &mut Engine, request: &FrameRequest, position: usize) -> Vec<FrameReport> {
    show_checking(engine, request, position, |_, _| {})
}

/// `show`, with `check` called after every frame (the clock stays still: runs repeat).
fn show_checking(
    engine: &mut Engine,
    request: &FrameRequest,
    position: usize,
    check: impl FnMut(&Engine, &FrameReport),
) -> Vec<FrameReport> {
    let pace = Pace {
        real_time: false,
        pause: Duration::from_millis(1),
        timeout: Duration::from_secs(120),
    };
    let mut request = request.clone();
    engine
        .show_and_wait(&mut request, position, pace, check)
        .unwrap()
}

/// Bytes step `index` holds on the GPU, predicted by its host half and checked against the
/// buffers it gets.
fn step_bytes(dir: &Path, gpu: &Gpu, index: usize) -> u64 {
    let host = HostStep::open(&dir.join(step_file_name(index)), None).unwrap();
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    let step = GpuStep::create(gpu, &host, &mut encoder).unwrap();
    assert_eq!(step.gpu_bytes(), host.gpu_bytes(), "predicted bytes differ");
    step.gpu_bytes()
}

/// The engine's picture on screen is a direct render of step `index` at the request's
/// iterations, hit for hit and pixel for pixel; that render.
fn assert_shows_the_direct_render(
    engine: &Engine,
    gpu: &Gpu,
    dir: &Path,
    index: usize,
    request: &FrameRequest,
) -> Frame {
    let targets = engine.targets().unwrap();
    let shown = engine.tracer().read_frame(gpu, targets).unwrap();
    let file = slosh_cache::CacheFile::open(&dir.join(step_file_name(index))).unwrap();
    let step = GpuStep::upload(gpu, &file, None).unwrap();
    let direct = engine
        .tracer()
        .render(gpu, &step, &request.camera, &request.params)
        .unwrap();
    assert!(shown.hits == direct.hits, "hits differ");
    assert!(shown.rgba == direct.rgba, "pixels differ");
    direct
}

#[test]
fn streams_under_a_tiny_budget_with_stand_ins_and_never_evicts_the_shown_step() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    bake_series(dir.path(), 0..10, true);
    let bytes: Vec<u64> = (0..10).map(|i| step_bytes(dir.path(), &gpu, i)).collect();
    let largest = bytes.iter().copied().max().unwrap();
    // Room for two steps and a half: every new step evicts one.
    let budget = largest * 5 / 2;
    let options = EngineOptions {
        budget: Some(budget),
        loaders: 2,
        ..EngineOptions::default()
    };
    let mut engine = Engine::open(gpu.clone(), dir.path(), options).unwrap();
    assert_eq!(engine.timeline().len(), 10);
    let request = request(1);
    let first = show(&mut engine, &request, 0);
    assert!(
        first[0].shown.is_none(),
        "nothing is resident at the first frame"
    );
    let since = first.iter().position(|r| r.shown.is_some()).unwrap();
    assert!(
        first[since..].iter().all(|r| r.shown.is_some()),
        "once a step is shown the frame is never blank"
    );
    let mut after_first_jump = 0;
    for (k, target) in [7, 2, 9, 0, 5, 6, 1].into_iter().enumerate() {
        if k == 1 {
            after_first_jump = engine.fresh_buffers().sections;
        }
        let reports = show_checking(&mut engine, &request, target, |engine, r| {
            let shown = r.shown.expect("a step is always shown once one was");
            assert!(
                engine.resident().contains(&shown),
                "shown step {shown} was evicted"
            );
            assert_eq!(r.stand_in, shown != target);
            assert!(engine.used_bytes() <= budget);
            // A step may hold section buffers of a step dropped before it, up to a
            // sixteenth larger than its own (`BufferShelf`): the pool counts what is held.
            let held: u64 = engine.resident().iter().map(|&i| bytes[i]).sum();
            let used = engine.used_bytes();
            assert!(
                used >= held && used <= held + held / 16,
                "{used} bytes counted for buffers of {held}"
            );
        });
        assert!(
            reports.len() == 1 || reports[0].stand_in,
            "a step not yet resident is drawn by a stand-in first"
        );
        assert!(engine.resident().contains(&target));
        assert!(engine.resident().len() <= 2);
    }
    assert!(engine.failures().is_empty());
    // Steps dropped from the pool leave their section buffers to the next uploads: the six
    // later jumps (their steps and the loaders' window) made fewer than half as many as
    // their own steps hold.
    let later = engine.fresh_buffers().sections - after_first_jump;
    let per_step = section_buffers(dir.path(), &gpu, 0);
    eprintln!(
        "{later} section buffers made in six jumps, {per_step} a step; {} bytes kept",
        engine.shelved_bytes()
    );
    assert!(per_step >= 5, "{per_step} section buffers a step");
    assert!(
        later * 2 < 6 * per_step,
        "{later} section buffers made anew"
    );
    // A step's worth for each of the 2 loaders and 2 more, each buffer up to a sixteenth
    // larger than the step that gave it.
    assert!(engine.shelved_bytes() <= 4 * (largest + largest / 16));
}

/// How many section buffers step `index` takes (its sections that hold bytes).
fn section_buffers(dir: &Path, gpu: &Gpu, index: usize) -> usize {
    let host = HostStep::open(&dir.join(step_file_name(index)), None).unwrap();
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    let shelf = slosh_render::BufferShelf::new();
    let options = slosh_render::UploadOptions {
        shelf: Some(&shelf),
        ..Default::default()
    };
    drop(GpuStep::create_in(gpu, &host, &mut encoder, options).unwrap());
    shelf.fresh()
}

#[test]
fn a_series_that_fits_ends_up_wholly_resident() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    bake_series(dir.path(), 0..8, true);
    let bytes: Vec<u64> = (0..8).map(|i| step_bytes(dir.path(), &gpu, i)).collect();
    let options = EngineOptions {
        budget: Some(bytes.iter().sum::<u64>() * 2),
        loaders: 2,
        ..EngineOptions::default()
    };
    let mut engine = Engine::open(gpu, dir.path(), options).unwrap();
    let request = request(1);
    show(&mut engine, &request, 3);
    for _ in 0..2000 {
        if engine.resident().len() == 8 {
            break;
        }
        frame(&mut engine, &request);
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!(engine.resident(), (0..8).collect::<Vec<_>>());
    assert_eq!(engine.used_bytes(), bytes.iter().sum::<u64>());
}

#[test]
fn finished_refinement_equals_a_direct_render() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    bake_series(dir.path(), 0..2, true);
    let mut engine = Engine::open(gpu.clone(), dir.path(), EngineOptions::default()).unwrap();
    let request = request(3);
    let reports = show(&mut engine, &request, 1);
    assert_eq!(reports.last().unwrap().drawn, Some(1));
    let drawn: Vec<Option<u32>> = (0..4).map(|_| frame(&mut engine, &request).drawn).collect();
    assert_eq!(drawn, vec![Some(2), Some(3), None, None]);
    assert!(frame(&mut engine, &request).progress.unwrap().finished());
    let direct = assert_shows_the_direct_render(&engine, &gpu, dir.path(), 1, &request);
    let lit = direct.hits.iter().filter(|h| h.status != 0).count();
    assert!(lit > 200, "{lit} hit pixels");
    // Moving the camera starts over at one iteration.
    let mut moving = request.clone();
    moving.camera_moving = true;
    moving.camera.eye[0] += 0.1;
    assert_eq!(frame(&mut engine, &moving).drawn, Some(1));
}

/// Under a frame budget far below a frame's cost, a still view is drawn as a preview, then
/// its masks in parts and its levels as sets of rows, one per frame: the finished picture is
/// the direct render's, and a probe of its pixels reads the surface back.
#[test]
fn a_frame_budget_refines_in_parts_to_the_direct_render_and_probes_it() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    bake_series(dir.path(), 0..2, true);
    let mut engine = Engine::open(gpu.clone(), dir.path(), EngineOptions::default()).unwrap();
    let mut request = request(3);
    request.frame_budget_ms = Some(0.001);
    show(&mut engine, &request, 1);
    let mut reports = Vec::new();
    while !reports
        .last()
        .is_some_and(|r: &FrameReport| r.progress.is_some_and(|p| p.finished()))
    {
        assert!(reports.len() < 5000, "no end to the refinement");
        reports.push(frame(&mut engine, &request));
    }
    let sets = reports
        .iter()
        .filter(|r| matches!(r.draw, Some(Draw::Rows { .. })))
        .count();
    let parts = reports.iter().filter(|r| r.masks.is_some()).count();
    eprintln!(
        "{} frames: {parts} mask parts, {sets} row sets",
        reports.len()
    );
    assert!(
        sets > 3 && parts >= 1,
        "{sets} row sets, {parts} mask parts"
    );
    assert_eq!(
        reports.last().unwrap().quality,
        Some(Quality {
            scale: 1.0,
            iterations: 3
        })
    );
    let direct = assert_shows_the_direct_render(&engine, &gpu, dir.path(), 1, &request);
    // Moving: a preview, smaller than the frame.
    let mut moving = request.clone();
    moving.camera_moving = true;
    let report = frame(&mut engine, &moving);
    assert_eq!(report.draw, Some(Draw::Preview));
    assert!(report.quality.unwrap().scale < 1.0);
    // Probes of the refined picture: a miss in the corner; the centre on the surface, within
    // two spacings of its nearest particle, which names its input index.
    for _ in 0..2000 {
        if frame(&mut engine, &request).progress.unwrap().finished() {
            break;
        }
    }
    // A pixel is read back, and the first probe of a step asks for its surface on a thread of
    // its own: none until both are read.
    let mut settled = |x: u32, y: u32| {
        assert!(engine.probe(x, y, 1.0).unwrap().is_none());
        assert!(engine.probe_preparing(), "the pixel was read at once");
        let started = std::time::Instant::now();
        loop {
            let probe = engine.probe(x, y, 1.0).unwrap();
            if probe.is_some() || !engine.probe_preparing() {
                break probe;
            }
            assert!(started.elapsed().as_secs() < 60, "the probe never came");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    assert!(settled(0, 0).is_none());
    let probe = settled(32, 24).expect("no probe, and none being prepared");
    let file = slosh_cache::CacheFile::open(&dir.path().join(step_file_name(1))).unwrap();
    let header = file.header();
    let spacing = header.spacing * header.transform.scale;
    assert_eq!(probe.step, 1);
    assert!(
        probe.reading.nearest_distance < 2.0 * spacing,
        "{probe:?}, spacing {spacing}"
    );
    // Baked in memory, from no case on disk: said, not guessed.
    let why = probe.input.unwrap_err();
    assert!(why.contains("cannot be read"), "{why}");
    let hit = &direct.hits[24 * 64 + 32];
    let world = header.transform.to_world(hit.position.map(f64::from));
    assert_eq!(probe.reading.world, world);
}

#[test]
fn bad_steps_are_marked_and_a_growing_series_is_picked_up() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    // A bake in progress: two steps, no manifest yet.
    bake_series(dir.path(), 0..2, false);
    let mut engine = Engine::open(gpu, dir.path(), EngineOptions::default()).unwrap();
    assert_eq!(engine.timeline().len(), 2);
    let request = request(1);
    show(&mut engine, &request, 1);
    bake_series(dir.path(), 2..4, false);
    // A step whose bytes were damaged after it landed.
    let bad = dir.path().join(step_file_name(4));
    std::fs::copy(dir.path().join(step_file_name(0)), &bad).unwrap();
    let balls = slosh_cache::CacheFile::open(&bad)
        .unwrap()
        .section(slosh_cache::names::BALLS)
        .unwrap()
        .offset as usize;
    let mut bytes = std::fs::read(&bad).unwrap();
    bytes[balls + 10] ^= 0x40;
    std::fs::write(&bad, bytes).unwrap();
    assert!(engine.refresh_series().unwrap());
    assert_eq!(engine.timeline().len(), 5);
    assert_eq!(engine.timeline().current(), 1, "the shown step stays");
    show(&mut engine, &request, 3);
    engine.timeline_mut().set_current(4);
    let mut failed = None;
    for _ in 0..5000 {
        let report = frame(&mut engine, &request);
        assert!(report.shown.is_some(), "the app goes on showing a step");
        if let Some(f) = engine.failures().into_iter().find(|(p, _)| *p == 4) {
            failed = Some(f.1);
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let why = failed.expect("the damaged step is reported");
    assert!(why.contains("step-00004.slc"), "{why}");
    assert_eq!(engine.failures().len(), 1);
    // The step before it still plays.
    show(&mut engine, &request, 2);
}

/// Exports until the job ends (two minutes at most).
fn finish(job: &mut ExportJob) -> ExportState {
    let start = std::time::Instant::now();
    loop {
        match job.poll() {
            ExportState::Running { .. } => {
                assert!(start.elapsed() < Duration::from_secs(120), "export hangs");
                std::thread::sleep(Duration::from_millis(10));
            }
            ended => return ended,
        }
    }
}

/// The export job, headless: each step's PNG is byte for byte the direct render of that
/// step; an empty range is refused; a junk step ends the job with an error naming its file,
/// after the frames before it.
#[test]
fn an_export_job_writes_each_step_as_a_direct_render() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    bake_series(dir.path(), 0..3, true);
    let out = tempfile::tempdir().unwrap();
    let params = TraceParams {
        iterations: 2,
        ..TraceParams::default()
    };
    let request = ExportRequest {
        steps: (0..3)
            .map(|i| (i, dir.path().join(step_file_name(i))))
            .collect(),
        camera: camera(),
        params,
        field: None,
        dir: out.path().join("frames"),
        movie: None,
        labels: false,
    };
    let mut job = ExportJob::spawn(gpu.clone(), request.clone()).unwrap();
    let ended = finish(&mut job);
    let expected = ExportState::Finished {
        frames: 3,
        dir: request.dir.clone(),
    };
    assert_eq!(ended, expected);
    let tracer = Tracer::new(&gpu).unwrap();
    for (i, path) in &request.steps {
        let file = slosh_cache::CacheFile::open(path).unwrap();
        let (_, frame) = trace_file(&gpu, &tracer, &file, None, &camera(), &params).unwrap();
        let lit = frame.hits.iter().filter(|h| h.status != 0).count();
        assert!(lit > 200, "step {i}: {lit} hit pixels");
        let direct = out.path().join(format!("direct-{i}.png"));
        slosh_render::write_frame_png(&direct, &frame).unwrap();
        let exported = std::fs::read(frame_path(&request.dir, *i)).unwrap();
        assert!(
            exported == std::fs::read(&direct).unwrap(),
            "step {i} differs"
        );
    }
    // With labels, the time is drawn over the frame's top half; the rest of it is the
    // direct render's.
    let labelled = ExportRequest {
        dir: out.path().join("labelled"),
        labels: true,
        ..request.clone()
    };
    let mut job = ExportJob::spawn(gpu.clone(), labelled.clone()).unwrap();
    assert!(matches!(
        finish(&mut job),
        ExportState::Finished { frames: 3, .. }
    ));
    let rows = |path: &Path| {
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        reader.next_frame(&mut buf).unwrap();
        buf
    };
    let plain = rows(&frame_path(&request.dir, 1));
    let marked = rows(&frame_path(&labelled.dir, 1));
    // The label is about 10 pixels tall at this size (its smallest), from row 6.
    let top = 48 / 2 * 64 * 3;
    assert!(plain[..top] != marked[..top], "no label in the top half");
    assert!(
        plain[top..] == marked[top..],
        "the label spilled below the top half"
    );
    // The same range as one MP4: a sample per step, each shown for its duration.
    let path = out.path().join("movie").join("range.mp4");
    let seconds = vec![0.1, 0.2, 0.3];
    let movie = ExportRequest {
        movie: Some(slosh_play::export::MovieRequest {
            path: path.clone(),
            seconds: seconds.clone(),
        }),
        ..request.clone()
    };
    let mut job = ExportJob::spawn(gpu.clone(), movie).unwrap();
    assert_eq!(
        finish(&mut job),
        ExportState::Finished {
            frames: 3,
            dir: path.clone()
        }
    );
    let bytes = std::fs::read(&path).unwrap();
    let reader =
        mp4::Mp4Reader::read_header(std::io::Cursor::new(&bytes), bytes.len() as u64).unwrap();
    let track = reader.tracks().values().next().unwrap();
    assert_eq!(track.sample_count(), 3);
    let lasts = track.duration().as_secs_f64();
    assert!((lasts - 0.6).abs() < 1e-3, "the movie lasts {lasts} s");
    let none = ExportRequest {
        steps: Vec::new(),
        ..request.clone()
    };
    assert!(ExportJob::spawn(gpu.clone(), none).is_err());
    let junk = dir.path().join("junk.slc");
    std::fs::write(&junk, b"not a cache file").unwrap();
    let bad = ExportRequest {
        steps: vec![request.steps[0].clone(), (7, junk)],
        dir: out.path().join("bad"),
        ..request
    };
    let mut job = ExportJob::spawn(gpu, bad).unwrap();
    match finish(&mut job) {
        ExportState::Failed(why) => assert!(why.contains("junk.slc"), "{why}"),
        other => panic!("a junk step ended the export as {other:?}"),
    }
    assert!(frame_path(&out.path().join("bad"), 0).exists());
    assert!(!frame_path(&out.path().join("bad"), 7).exists());
}

/// Steps `0..count` of the moving 1500-point sphere written as an EnSight 6 binary case with
/// its normals, under `dir`; the case's path.
fn write_case(dir: &Path, count: usize) -> std::path::PathBuf {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 1500, 3)).unwrap();
    slosh_testkit::write_surface_case(dir, "sphere", &scene, count).unwrap()
}

/// Shows `position` and refines it to the request's iterations.
fn show_refined(engine: &mut Engine, request: &FrameRequest, position: usize) {
    show(engine, request, position);
    for _ in 0..100 {
        if frame(engine, request)
            .progress
            .is_some_and(|p| p.finished())
        {
            return;
        }
    }
    panic!("step {position} did not finish refining in 100 frames");
}

/// The case's steps, baked on demand into `cache` by `slosh bake`'s settings for it.
fn on_demand(case: &Path, cache: &Path) -> slosh_bake::OnDemand {
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let opened = slosh_ensight::Case::open(case).unwrap();
    let cpu = slosh_bake::Stages::cpu();
    slosh_bake::OnDemand::of_case(opened, case, cache.to_path_buf(), params, (1, 1), cpu).unwrap()
}

/// A raw case's engine asks for a step ahead for every loader (each bakes one, for hundreds of
/// milliseconds): with 8 loaders whose loads take 2 s, steps 1 to 8 are all asked for once
/// step 0 shows, where a window of the rate's half second held 4.
#[test]
fn a_raw_case_asks_for_a_step_ahead_for_every_loader() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let case = write_case(&dir.path().join("case"), 12);
    let cache = dir.path().join("cache");
    let mut engine = Engine::open_baking(
        gpu,
        Arc::new(on_demand(&case, &cache)),
        EngineOptions {
            loaders: 8,
            load_delay: Some(Duration::from_secs(2)),
            ..EngineOptions::default()
        },
    )
    .unwrap();
    let request = request(1);
    show(&mut engine, &request, 0);
    frame(&mut engine, &request);
    let asked = engine.prefetching();
    assert!((1..=8).all(|p| asked.contains(&p)), "asked for {asked:?}");
}

/// A raw case plays with no bake first: every step is a position from the start, a step is
/// baked into the cache directory by the loader that first needs it and shows what `slosh
/// bake` of the same case renders, a step whose files are damaged is a failed step while the
/// others play, and the next run finds the steps baked and bakes none again.
#[test]
fn a_raw_case_is_baked_as_it_plays_and_stays_baked() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let case = write_case(&dir.path().join("case"), 4);
    // Step 2's geometry cut short.
    let geometry = dir.path().join("case/sphere.geo00002");
    let bytes = std::fs::read(&geometry).unwrap();
    std::fs::write(&geometry, &bytes[..bytes.len() / 2]).unwrap();
    let cache = dir.path().join("cache");
    let mut engine = Engine::open_baking(
        gpu.clone(),
        Arc::new(on_demand(&case, &cache)),
        EngineOptions::default(),
    )
    .unwrap();
    assert_eq!(
        engine.timeline().len(),
        4,
        "every step is a position at once"
    );
    assert!(engine.baked().is_empty());
    assert!(!cache.join(step_file_name(1)).exists());
    let request = request(3);
    show_refined(&mut engine, &request, 1);
    let baked = cache.join(step_file_name(1));
    slosh_cache::CacheFile::open(&baked)
        .unwrap()
        .verify()
        .unwrap();
    let shown = assert_shows_the_direct_render(&engine, &gpu, &cache, 1, &request);
    // The same step baked by the batch driver (`slosh bake`) renders the same.
    let batch = dir.path().join("batch");
    let source = slosh_bake::EnsightSource::new(
        slosh_ensight::Case::open(&case).unwrap(),
        &case,
        slosh_ensight::PointSource::Auto,
        &BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into())),
    );
    let opts = slosh_bake::BatchOptions {
        out: batch.clone(),
        steps: Some((1, 1)),
        jobs: 1,
        threads: 1,
        shard: slosh_bake::Shard::WHOLE,
        params: BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into())),
        stages: slosh_bake::Stages::cpu(),
    };
    let report = slosh_bake::run_batch(&source, &opts, &|_| {}).unwrap();
    assert_eq!(report.baked, 1);
    let file = slosh_cache::CacheFile::open(&batch.join(step_file_name(1))).unwrap();
    let step = GpuStep::upload(&gpu, &file, None).unwrap();
    let direct = engine
        .tracer()
        .render(&gpu, &step, &request.camera, &request.params)
        .unwrap();
    assert!(
        shown.hits == direct.hits,
        "the batch's bake renders otherwise"
    );
    // The damaged step fails; the one after it plays.
    engine.timeline_mut().set_current(2);
    let mut failed = None;
    for _ in 0..5000 {
        frame(&mut engine, &request);
        if let Some(f) = engine.failures().into_iter().find(|(p, _)| *p == 2) {
            failed = Some(f.1);
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let why = failed.expect("the step that cannot be read is reported");
    assert!(
        why.contains("did not bake") && why.contains("sphere.geo00002"),
        "{why}"
    );
    assert!(!cache.join(step_file_name(2)).exists(), "no file for it");
    show(&mut engine, &request, 3);
    engine.refresh_series().unwrap();
    assert!(engine.baked().contains(&1) && engine.baked().contains(&3));
    assert!(!engine.baked().contains(&2));
    drop(engine);
    // The next run: step 1 is there, and is not baked again.
    let stamp = std::fs::metadata(&baked).unwrap().modified().unwrap();
    let mut engine = Engine::open_baking(
        gpu.clone(),
        Arc::new(on_demand(&case, &cache)),
        EngineOptions::default(),
    )
    .unwrap();
    assert!(engine.baked().contains(&1));
    show_refined(&mut engine, &request, 1);
    assert_eq!(
        std::fs::metadata(&baked).unwrap().modified().unwrap(),
        stamp
    );
    assert_shows_the_direct_render(&engine, &gpu, &cache, 1, &request);
}
