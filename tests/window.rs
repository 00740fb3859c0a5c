//! The player in a real window: Xvfb, lavapipe, and real X input events (XTEST, through
//! xdotool). Keys move and play, a drag orbits, the X screen capture shows what `slosh
//! render` makes of the same step and camera, a corrupted step is marked while the app goes
//! on, and a slow step source never stops the UI. Required under `CI=true`; skipped with a
//! message where Xvfb, xdotool or ImageMagick's `import` is missing.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod util;

use util::{have, in_ci, slosh_ok as slosh};

/// Kills the child when dropped (the test may fail half-way).
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        // SIGTERM first, so that Xvfb removes its lock file and socket.
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        for _ in 0..50 {
            if self.0.try_wait().is_ok_and(|s| s.is_some()) {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

struct Display {
    name: String,
    _server: Guard,
}

impl Display {
    fn start() -> Display {
        Display::start_sized("1024x768")
    }

    /// A screen of `size` (WxH).
    fn start_sized(size: &str) -> Display {
        // Xvfb picks a free display and writes its number to the pipe (-displayfd), so tests
        // running side by side never share one.
        let mut server = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                &format!("{size}x24"),
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let stdout = server.stdout.take().unwrap();
        std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line).unwrap();
        let number: u32 = line
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("Xvfb said '{line}'"));
        let display = Display {
            name: format!(":{number}"),
            _server: Guard(server),
        };
        wait_for("Xvfb", Duration::from_secs(20), || {
            display.xdotool(&["getdisplaygeometry"]).is_some()
        });
        display
    }

    fn xdotool(&self, args: &[&str]) -> Option<String> {
        let out = Command::new("xdotool")
            .args(args)
            .env("DISPLAY", &self.name)
            .output()
            .ok()?;
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
    }

    /// The whole screen, as captured by the X server (ImageMagick's `import`).
    fn capture(&self, path: &Path) -> (u32, u32, Vec<u8>) {
        let ok = Command::new("import")
            .args(["-window", "root", path.to_str().unwrap()])
            .env("DISPLAY", &self.name)
            .status()
            .unwrap()
            .success();
        assert!(ok, "import failed");
        rgb(path)
    }
}

fn wait_for(what: &str, limit: Duration, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(start.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A PNG as RGB8.
fn rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let pixels: Vec<u8> = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    (info.width, info.height, pixels)
}

fn crop(image: &(u32, u32, Vec<u8>), x: u32, y: u32, w: u32, h: u32) -> Vec<u8> {
    let (width, _, pixels) = image;
    (y..y + h)
        .flat_map(|row| {
            let start = ((row * width + x) * 3) as usize;
            pixels[start..start + (w * 3) as usize].to_vec()
        })
        .collect()
}

/// A baked series of `steps` steps of the sloshing tank with droplets, coloured by pressure.
/// The droplets scene, 8000 particles, `steps` steps 0.02 s apart, written as a case under
/// `dir/case`; the case file.
fn droplets_case(dir: &Path, steps: usize) -> PathBuf {
    let case = dir.join("case");
    slosh(&[
        "gen",
        "droplets",
        "--points",
        "8000",
        "--steps",
        &steps.to_string(),
        "--dt",
        "0.02",
        "--out",
        case.to_str().unwrap(),
    ]);
    case.join("droplets.case")
}

/// [`droplets_case`] baked with its pressure into `dir/cache`.
fn series(dir: &Path, steps: usize) -> PathBuf {
    let case = droplets_case(dir, steps);
    let cache = dir.join("cache");
    slosh(&[
        "bake",
        case.to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
        "--fields",
        "pressure",
        "--quiet",
    ]);
    cache
}

/// Flips a byte inside step `index`'s balls section: the file opens, its data fails.
fn corrupt(cache: &Path, index: usize) {
    let path = cache.join(slosh_cache::step_file_name(index));
    let offset = slosh_cache::CacheFile::open(&path)
        .unwrap()
        .section(slosh_cache::names::BALLS)
        .unwrap()
        .offset as usize;
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[offset + 100] ^= 0x08;
    std::fs::write(&path, bytes).unwrap();
}

struct Player {
    _process: Guard,
    log: PathBuf,
    window: String,
}

impl Player {
    fn start(display: &Display, cache: &Path, out: &Path, extra: &[&str]) -> Player {
        Player::start_in(display, cache, out, "640x480", extra)
    }

    /// A player in a window of `window` (WxH).
    fn start_in(
        display: &Display,
        cache: &Path,
        out: &Path,
        window: &str,
        extra: &[&str],
    ) -> Player {
        let log = out.join("player.log");
        let mut process = Command::new(env!("CARGO_BIN_EXE_slosh"))
            .args([
                "play",
                cache.to_str().unwrap(),
                "--window",
                window,
                "--output",
                out.to_str().unwrap(),
                "--log-frames",
            ])
            .args(extra)
            .env("DISPLAY", &display.name)
            .stdout(std::fs::File::create(&log).unwrap())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut window = String::new();
        wait_for("the player's window", Duration::from_secs(120), || {
            // A player that ended says why, where a window that never came only timed out.
            if let Ok(Some(status)) = process.try_wait() {
                let said = std::fs::read_to_string(&log).unwrap_or_default();
                panic!(
                    "the player ended ({status}) before its window came (its stderr is above); its log:\n{said}"
                );
            }
            window = display
                .xdotool(&["search", "--name", "^slosh"])
                .and_then(|w| w.lines().next().map(str::to_string))
                .unwrap_or_default();
            !window.is_empty()
        });
        Player {
            _process: Guard(process),
            log,
            window,
        }
    }

    /// A key press through XTEST, as a person's: there is no window manager, so the window
    /// is given the focus and the pointer first.
    fn key(&self, display: &Display, key: &str) {
        display.xdotool(&["windowfocus", "--sync", &self.window]);
        display.xdotool(&["mousemove", "--window", &self.window, "150", "150"]);
        display.xdotool(&["key", key]).unwrap();
    }

    fn title(&self, display: &Display) -> String {
        display
            .xdotool(&["getwindowname", &self.window])
            .unwrap_or_default()
    }

    fn wait_title(&self, display: &Display, wanted: &str) {
        wait_for(
            &format!("a title with '{wanted}'"),
            Duration::from_secs(60),
            || self.title(display).contains(wanted),
        );
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn alive(&mut self) -> bool {
        self._process.0.try_wait().is_ok_and(|s| s.is_none())
    }
}

/// Window tests take turns: each runs a software GPU (lavapipe) flat out, and side by side
/// on two cores their timing assertions (passes per second) would measure each other.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Holds the turn of one window test.
fn turn() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn tools() -> bool {
    let missing: Vec<&str> = ["Xvfb", "xdotool", "import"]
        .into_iter()
        .filter(|t| !have(t))
        .collect();
    if missing.is_empty() {
        return true;
    }
    assert!(
        !in_ci(),
        "CI=true requires {missing:?} for the window tests"
    );
    eprintln!("skipping the window test: {missing:?} missing");
    false
}

#[test]
fn keys_drag_and_the_screen_agree_with_slosh_render() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let cache = series(dir.path(), 6);
    corrupt(&cache, 4);
    let display = Display::start();
    let mut player = Player::start(
        &display,
        &cache,
        dir.path(),
        &["--field", "pressure", "--field-range", "step"],
    );
    player.wait_title(&display, "step 0/5, t = 0.000");

    // → moves to the next step.
    player.key(&display, "Right");
    player.wait_title(&display, "step 1/5");

    // Space plays: with loop off it runs to the last step and stops; the corrupted step 4 is
    // reported on the way, and the app goes on.
    player.key(&display, "space");
    player.wait_title(&display, "step 5/5");
    wait_for("the failure of step 4", Duration::from_secs(60), || {
        player.log().contains("failed step 4:")
    });
    let log = player.log();
    let failure = log
        .lines()
        .find(|l| l.starts_with("failed step 4:"))
        .unwrap();
    assert!(failure.contains("step-00004.slc"), "{failure}");
    assert!(player.alive(), "the player died on a corrupted step");

    // Home, then → again: step 1, refined and still.
    player.key(&display, "Home");
    player.wait_title(&display, "step 0/5");
    player.key(&display, "Right");
    player.wait_title(&display, "step 1/5");
    std::thread::sleep(Duration::from_secs(3));
    let before = display.capture(&dir.path().join("before.png"));

    // A drag with the left button orbits the camera: the viewport changes, the step stays.
    display.xdotool(&["mousemove", "--window", &player.window, "150", "200"]);
    display.xdotool(&["mousedown", "1"]).unwrap();
    for x in [170, 190, 210, 230] {
        display.xdotool(&[
            "mousemove",
            "--window",
            &player.window,
            &x.to_string(),
            "190",
        ]);
        std::thread::sleep(Duration::from_millis(80));
    }
    display.xdotool(&["mouseup", "1"]).unwrap();
    std::thread::sleep(Duration::from_secs(3));
    let after = display.capture(&dir.path().join("after.png"));
    assert!(player.title(&display).contains("step 1/5"));
    let viewport = |img| crop(img, 0, 0, 300, 300);
    let changed = viewport(&before)
        .chunks_exact(3)
        .zip(viewport(&after).chunks_exact(3))
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed > 2000,
        "the drag changed only {changed} viewport pixels"
    );

    let shot = screenshot_against_render(
        &player,
        &display,
        dir.path(),
        &cache,
        1,
        &["--field", "pressure"],
    );
    let (w, h, vx, vy) = (shot.width, shot.height, shot.viewport.0, shot.viewport.1);
    let rendered = shot.rendered;
    // The X server's picture of the viewport, once the screenshot frame is on screen.
    std::thread::sleep(Duration::from_secs(2));
    let screen = display.capture(&dir.path().join("screen.png"));
    let geometry = display
        .xdotool(&["getwindowgeometry", "--shell", &player.window])
        .unwrap();
    let field = |key: &str| -> u32 {
        geometry
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.parse().ok())
            .unwrap()
    };
    let shown = crop(&screen, field("X=") + vx, field("Y=") + vy, w, h);
    // The screen: the same hit/miss pattern (the background is a vertical gradient of dark
    // blue-greys, the surface is lit) and colours within 3/255 but at a few edge pixels.
    let background = |p: &[u8]| p[2] > p[0] && p[0] < 40 && p[1] < 45;
    let mut pattern_differs = 0usize;
    let mut colour_differs = 0usize;
    let mut total_error = 0u64;
    for (a, b) in shown.chunks_exact(3).zip(rendered.chunks_exact(3)) {
        if background(a) != background(b) {
            pattern_differs += 1;
        }
        let e = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
        total_error += u64::from(e);
        if e > 3 {
            colour_differs += 1;
        }
    }
    let pixels = (w * h) as usize;
    let mean = total_error as f64 / pixels as f64;
    eprintln!(
        "screen vs render, {w}x{h}: {pattern_differs} pixels differ in hit/miss, {colour_differs} by more than 3/255, mean max-channel error {mean:.3}"
    );
    assert!(
        pattern_differs * 1000 <= pixels,
        "{pattern_differs} hit/miss differences"
    );
    assert!(
        colour_differs * 200 <= pixels,
        "{colour_differs} colour differences"
    );
    assert!(mean < 1.0, "mean error {mean}");
    // Keep the captures for the closing note and the README when asked.
    if let Some(keep) = std::env::var_os("SLOSH_KEEP_SCREENS") {
        let keep = PathBuf::from(keep);
        std::fs::create_dir_all(&keep).unwrap();
        for name in ["screen.png", "slosh-step-00001.png", "render.png"] {
            std::fs::copy(dir.path().join(name), keep.join(name)).unwrap();
        }
        // The whole window, as the X server shows it.
        let (ww, wh) = (field("WIDTH="), field("HEIGHT="));
        let window = crop(&screen, field("X="), field("Y="), ww, wh);
        slosh_render::write_rgb_png(&keep.join("window.png"), ww, wh, &window).unwrap();
    }
    assert!(player.alive());
}

/// The app's own screenshot (F12) of step `step` and `slosh render` of the same view, the
/// camera read from the screenshot's log line; the two must be the same pixels.
struct Screenshot {
    width: u32,
    height: u32,
    /// The viewport's offset in the window.
    viewport: (u32, u32),
    /// `slosh render`'s pixels (RGB).
    rendered: Vec<u8>,
}

fn screenshot_against_render(
    player: &Player,
    display: &Display,
    dir: &Path,
    cache: &Path,
    step: usize,
    render_extra: &[&str],
) -> Screenshot {
    let shots = |log: &str| log.lines().filter(|l| l.starts_with("screenshot ")).count();
    let before = shots(&player.log());
    player.key(display, "F12");
    wait_for("the screenshot", Duration::from_secs(120), || {
        shots(&player.log()) > before
    });
    let log = player.log();
    let line = log
        .lines()
        .filter(|l| l.starts_with("screenshot "))
        .nth(before)
        .unwrap()
        .to_string();
    eprintln!("{line}");
    let after_colon = line.split_once("): ").unwrap().1;
    let words: Vec<&str> = after_colon.split_whitespace().collect();
    let flag = |name: &str| {
        let i = words.iter().position(|w| *w == name).unwrap();
        words[i + 1].to_string()
    };
    let size = flag("--size");
    let (width, height): (u32, u32) = {
        let (a, b) = size.split_once('x').unwrap();
        (a.parse().unwrap(), b.parse().unwrap())
    };
    let at = line.split_once("viewport at ").unwrap().1;
    let at = at.split_once(' ').unwrap().0;
    let (vx, vy) = at.split_once(',').unwrap();
    let viewport = (
        vx.parse::<f32>().unwrap() as u32,
        vy.parse::<f32>().unwrap() as u32,
    );
    let render = dir.join("render.png");
    let step = step.to_string();
    let mut args = vec![
        "render",
        cache.to_str().unwrap(),
        "--step",
        &step,
        "--size",
        &size,
    ];
    let camera: Vec<(&str, String)> = ["--eye", "--target", "--up", "--fov", "--iterations"]
        .into_iter()
        .map(|f| (f, flag(f)))
        .collect();
    for (f, v) in &camera {
        args.extend_from_slice(&[f, v.as_str()]);
    }
    args.extend_from_slice(render_extra);
    args.extend_from_slice(&["--out", render.to_str().unwrap()]);
    slosh(&args);
    let (rw, rh, rendered) = rgb(&render);
    assert_eq!((rw, rh), (width, height));
    // The app's own screenshot is the render, pixel for pixel.
    let own = rgb(&dir.join(format!(
        "slosh-step-{:05}.png",
        step.parse::<usize>().unwrap()
    )));
    assert!(
        own.2 == rendered,
        "the app's screenshot differs from slosh render"
    );
    Screenshot {
        width,
        height,
        viewport,
        rendered,
    }
}

/// With every load taking 1.5 s, the UI keeps drawing: the frame counter advances and the
/// last shown step stands in until the new one is resident.
#[test]
fn a_slow_step_source_never_stops_the_ui() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let cache = series(dir.path(), 4);
    let display = Display::start();
    let player = Player::start(
        &display,
        &cache,
        dir.path(),
        &["--load-delay-ms", "1500", "--loaders", "1"],
    );
    player.wait_title(&display, "step 0/3");
    let passes = |log: &str| log.lines().filter(|l| l.starts_with("pass ")).count();
    let before = passes(&player.log());
    player.key(&display, "End");
    // While step 3 loads, the window shows step 0 as a stand-in and keeps drawing.
    std::thread::sleep(Duration::from_millis(1000));
    let log = player.log();
    let during = passes(&log);
    let tail: Vec<&str> = log.lines().rev().take(15).collect();
    assert!(
        log.lines()
            .any(|l| l.contains("wanted 3 shown Some(") && l.contains("stand-in")),
        "no stand-in frame while step 3 loaded: {tail:#?}"
    );
    // A UI blocked on the load would draw none.
    assert!(
        during >= before + 3,
        "only {} UI passes in the first second of a 1.5 s load",
        during - before
    );
    player.wait_title(&display, "step 3/3");
}

/// A series of `steps` steps of a sphere baked with the settings `series` uses: another
/// series, steps of which a user might copy into the wrong directory.
fn other_series(dir: &Path, steps: usize) -> PathBuf {
    let case = dir.join("other-case");
    let cache = dir.join("other-cache");
    slosh(&[
        "gen",
        "sphere",
        "--points",
        "3000",
        "--steps",
        &steps.to_string(),
        "--out",
        case.to_str().unwrap(),
    ]);
    slosh(&[
        "bake",
        case.join("sphere.case").to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
        "--quiet",
    ]);
    cache
}

/// The failures the player logged, by bake index.
fn failures(log: &str, step: usize) -> Vec<String> {
    let prefix = format!("failed step {step}: ");
    log.lines()
        .filter_map(|l| l.strip_prefix(&prefix).map(str::to_string))
        .collect()
}

/// Steps checked against the series, numbered by bake index, through files changing under
/// the player (issue 25, items 7, 8 and 10): a step of another series copied in is failed
/// against the manifest; a removed step keeps every later step's number (title, F12); a
/// restored step plays again.
#[test]
fn steps_keep_their_numbers_and_are_checked_as_files_change() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let cache = series(dir.path(), 6);
    let other = other_series(dir.path(), 6);
    let step = |i: usize| cache.join(slosh_cache::step_file_name(i));
    let kept = dir.path().join("step-2.kept");
    std::fs::copy(step(2), &kept).unwrap();
    // Renamed into place, as a careful copy would be.
    std::fs::copy(other.join(slosh_cache::step_file_name(2)), cache.join("x")).unwrap();
    std::fs::rename(cache.join("x"), step(2)).unwrap();
    let display = Display::start();
    let player = Player::start(&display, &cache, dir.path(), &[]);
    player.wait_title(&display, "step 0/5");
    player.key(&display, "Right");
    player.wait_title(&display, "step 1/5");
    player.key(&display, "Right");
    wait_for("step 2's failure", Duration::from_secs(60), || {
        !failures(&player.log(), 2).is_empty()
    });
    let why = failures(&player.log(), 2).remove(0);
    assert!(
        why.contains("not step 2 of this series") && why.contains("sphere.case"),
        "{why}"
    );
    // Step 3 removed while playing: the later steps keep their numbers.
    std::fs::remove_file(step(3)).unwrap();
    player.key(&display, "End");
    player.wait_title(&display, "step 5/5");
    wait_for("step 3's removal", Duration::from_secs(30), || {
        failures(&player.log(), 3)
            .iter()
            .any(|w| w.contains("was removed"))
    });
    player.key(&display, "Left");
    player.wait_title(&display, "step 4/5");
    std::thread::sleep(Duration::from_secs(2));
    player.key(&display, "F12");
    wait_for("the screenshot", Duration::from_secs(60), || {
        player.log().contains("slosh-step-00004.png")
    });
    assert!(dir.path().join("slosh-step-00004.png").exists());
    // Step 2 restored: it loads again (its failure was against a file that is gone).
    std::fs::copy(&kept, cache.join("x")).unwrap();
    std::fs::rename(cache.join("x"), step(2)).unwrap();
    std::thread::sleep(Duration::from_secs(3));
    player.key(&display, "Home");
    player.wait_title(&display, "step 0/5");
    player.key(&display, "Right");
    player.key(&display, "Right");
    player.wait_title(&display, "step 2/5");
    // Files copied over in place while they play (`cp` truncates, then writes): a read of a
    // mapped file that shrank is a failed step, never a SIGBUS (item 5).
    player.key(&display, "space");
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(6) {
        for i in [0, 1, 4, 5] {
            std::fs::copy(other.join(slosh_cache::step_file_name(i)), step(i)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(30));
    }
    std::thread::sleep(Duration::from_secs(2));
    let mut player = player;
    assert!(
        player.alive(),
        "the player died while its files were copied over"
    );
}

/// Junk step files, and a budget smaller than one step, are failed steps the window names,
/// not an endless "waiting" or "loading" (issue 25, item 10).
#[test]
fn unreadable_steps_and_a_tiny_budget_are_said() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk");
    std::fs::create_dir_all(&junk).unwrap();
    for i in 0..3 {
        std::fs::write(
            junk.join(slosh_cache::step_file_name(i)),
            b"not a cache file",
        )
        .unwrap();
    }
    let display = Display::start();
    let out = dir.path().join("junk-out");
    std::fs::create_dir_all(&out).unwrap();
    let player = Player::start(&display, &junk, &out, &[]);
    wait_for("the junk steps' failures", Duration::from_secs(90), || {
        (0..3).all(|i| !failures(&player.log(), i).is_empty())
    });
    assert!(failures(&player.log(), 0)[0].contains("step-00000.slc"));
    drop(player);
    let cache = series(dir.path(), 2);
    let out = dir.path().join("budget-out");
    std::fs::create_dir_all(&out).unwrap();
    // 10 kB: a step of 755 points holds about 100 kB on the GPU.
    let player = Player::start(&display, &cache, &out, &["--budget", "0.00001"]);
    wait_for("the budget failure", Duration::from_secs(120), || {
        failures(&player.log(), 0)
            .iter()
            .any(|w| w.contains("more than the whole budget"))
    });
    // Said once, not loaded again and again.
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(failures(&player.log(), 0).len(), 1, "{}", player.log());
}

/// CPU seconds a process has used (user and system), from /proc.
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .unwrap()
        .1
        .split_whitespace()
        .collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    ticks / 100.0
}

/// Every key press counts, however slow the passes (issue 25, item 11); a player at rest
/// draws no passes beyond one a second and uses almost no CPU (item 12); a window larger than
/// the default texture limit (8192) and a render scale past the device's limit are drawn,
/// not a panic (item 6).
#[test]
fn presses_count_rest_is_quiet_and_huge_windows_live() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let cache = series(dir.path(), 10);
    let display = Display::start();
    let mut player = Player::start(&display, &cache, dir.path(), &["--render-scale", "2"]);
    player.wait_title(&display, "step 0/9");
    display.xdotool(&["windowfocus", "--sync", &player.window]);
    display.xdotool(&["mousemove", "--window", &player.window, "150", "150"]);
    display
        .xdotool(&[
            "key", "--delay", "1", "Right", "Right", "Right", "Right", "Right",
        ])
        .unwrap();
    player.wait_title(&display, "step 5/9");
    // At rest (refined and still, the loaders done): passes and CPU. Refinement at render
    // scale 2 takes a varying while on lavapipe: it is waited for, not guessed.
    wait_refined(&player, 5, 3, 0);
    std::thread::sleep(Duration::from_secs(2));
    let passes = |log: &str| log.lines().filter(|l| l.starts_with("pass ")).count();
    let pid = player._process.0.id();
    let (before, cpu) = (passes(&player.log()), cpu_seconds(pid));
    std::thread::sleep(Duration::from_secs(4));
    let (after, used) = (passes(&player.log()), cpu_seconds(pid) - cpu);
    eprintln!(
        "at rest: {} passes and {used:.2} CPU seconds in 4 s",
        after - before
    );
    assert!(after - before <= 6, "{} passes at rest", after - before);
    assert!(used < 0.4, "{used} CPU seconds at rest");
    // Past 8192 pixels a side (render scale 2 makes the frame 18000 wide), then back.
    display.xdotool(&["windowsize", &player.window, "9000", "9000"]);
    std::thread::sleep(Duration::from_secs(10));
    assert!(player.alive(), "the player died in a 9000-pixel window");
    display.xdotool(&["windowsize", &player.window, "640", "480"]);
    player.key(&display, "Right");
    player.wait_title(&display, "step 6/9");
    assert!(player.alive());
    let log = player.log();
    let errors: Vec<&str> = log.lines().filter(|l| l.contains("frame error")).collect();
    assert!(errors.is_empty(), "frames failed: {errors:?}");
}

/// The export range follows a series a bake is still filling (issue 25, item 13): opened on
/// the first shard of a job array (steps 0 and 3), it spans 0..=3; once the other shards land
/// it spans 0..=5 without being touched.
#[test]
fn the_export_range_follows_a_growing_series() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let case = dir.path().join("case");
    let cache = dir.path().join("cache");
    slosh(&[
        "gen",
        "droplets",
        "--points",
        "4000",
        "--steps",
        "6",
        "--out",
        case.to_str().unwrap(),
    ]);
    let bake = |shard: &str| {
        slosh(&[
            "bake",
            case.join("droplets.case").to_str().unwrap(),
            "--out",
            cache.to_str().unwrap(),
            "--shard",
            shard,
            "--quiet",
        ]);
    };
    bake("0/3");
    let display = Display::start();
    let player = Player::start(&display, &cache, dir.path(), &[]);
    player.wait_title(&display, "step 0/3");
    wait_for("an export range of 0..=3", Duration::from_secs(30), || {
        player.log().lines().any(|l| l.ends_with("export 0..=3"))
    });
    bake("1/3");
    bake("2/3");
    wait_for("an export range of 0..=5", Duration::from_secs(60), || {
        player.log().lines().any(|l| l.ends_with("export 0..=5"))
    });
    player.wait_title(&display, "/5");
}

/// A UI pass that followed a busy one (which asked for the next at once), in milliseconds,
/// less the time the UI thread waited, runnable, for a core: under CI two cores are shared
/// with Xvfb, xdotool, this test, SLURM's daemons and lavapipe's threads (a hardware GPU takes
/// no core from the UI).
struct BusyPass {
    /// Since the pass before: how long an input event waits on the player.
    interval: f64,
    /// This pass's own work (its frame recorded and its GPU work waited for).
    own: f64,
    /// The frame before, as eframe measured it: that pass's work and eframe's paint, without
    /// its waits for the window's surface and the present (`NAN` where it did not say).
    frame_work: f64,
    /// The log line, and the line of the pass before.
    line: String,
}

/// The passes in `log` after line `from` that followed a busy pass.
fn busy_intervals(log: &str, from: usize) -> Vec<BusyPass> {
    let mut out = Vec::new();
    let mut previous_busy = false;
    let mut previous = "";
    for line in log.lines().skip(from).filter(|l| l.starts_with("pass ")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some(at) = words.iter().position(|w| *w == "ms") else {
            continue;
        };
        // "interval/own work/waited for a core/the frame before's work", "-" where the kernel
        // or eframe does not say.
        let times: Vec<&str> = words[at + 1].split('/').collect();
        let interval: f64 = times[0].parse().unwrap();
        let own: f64 = times[1].parse().unwrap();
        let queued: f64 = times.get(2).and_then(|q| q.parse().ok()).unwrap_or(0.0);
        let frame_work: f64 = times
            .get(3)
            .and_then(|c| c.parse().ok())
            .unwrap_or(f64::NAN);
        if previous_busy {
            // The pass before drew what delayed this one.
            out.push(BusyPass {
                interval: interval - queued,
                own,
                frame_work: frame_work - queued,
                line: format!("{line} after {previous}"),
            });
        }
        previous_busy = words[at + 2] == "busy";
        previous = line;
    }
    out
}

/// Waits until the player has refined step `step` to `iterations` and rests.
fn wait_refined(player: &Player, step: usize, iterations: u32, from: usize) {
    let drew = format!("drew {iterations} ");
    let wanted = format!("wanted {step} shown Some({step})");
    wait_for(
        &format!("step {step} refined to {iterations} iterations"),
        Duration::from_secs(240),
        || {
            let log = player.log();
            let passes: Vec<&str> = log
                .lines()
                .skip(from)
                .filter(|l| l.starts_with("pass "))
                .collect();
            let refined = passes
                .iter()
                .rposition(|l| l.contains(&wanted) && l.contains(&drew));
            refined.is_some_and(|r| passes[r..].iter().any(|l| l.contains(" idle ")))
        },
    );
}

/// A slow GPU never freezes the UI (issue 28, item 2): on lavapipe, a 300k-point step in a
/// 1600×1000 window answers a key press and a drag with UI passes of at most 100 ms each
/// (the frame budget draws a moving view smaller, and refines a still one as interleaved
/// row sets and the neighbour masks in parts, one per pass); the still view then refines to
/// the pixels of `slosh render`. What the player decides is held to 100 ms without
/// exception: each pass's own work (its GPU work waited for; the pass at rest probes the
/// pixel under the pointer). The whole frame on the UI thread (a pass and eframe's paint)
/// is held to 100 ms for all but one pass in 100, 200 ms for every one. The interval between
/// passes also holds the waits for the window's surface and the present, which Xvfb and
/// lavapipe's queue decide: nine in ten within 100 ms, none over 250 ms. (A CI run saw 67 of
/// 1359 passes over 100 ms, the slowest 159.5 ms, with 20–56 ms of own work; a local run with
/// two CPU hogs beside it, none over 90 ms.)
#[test]
fn a_slow_gpu_answers_within_100_ms_and_still_refines_to_the_render() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let case = dir.path().join("case");
    let cache = dir.path().join("cache");
    slosh(&[
        "gen",
        "sphere",
        "--points",
        "300000",
        "--steps",
        "2",
        "--out",
        case.to_str().unwrap(),
    ]);
    slosh(&[
        "bake",
        case.join("sphere.case").to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
        "--quiet",
    ]);
    let display = Display::start_sized("1920x1200");
    let player = Player::start_in(&display, &cache, dir.path(), "1600x1000", &[]);
    player.wait_title(&display, "step 0/1");
    // The first refinement compiles the pipelines of each iteration count: not measured.
    wait_refined(&player, 0, 3, 0);
    let from = player.log().lines().count();

    // A key press: step 1, previewed, its masks derived in parts, refined in row sets.
    player.key(&display, "Right");
    player.wait_title(&display, "step 1/1");
    wait_refined(&player, 1, 3, from);
    // A drag while it rests, then two key presses and another drag mid-refinement.
    let drag = |to: i32| {
        display.xdotool(&["mousemove", "--window", &player.window, "500", "400"]);
        display.xdotool(&["mousedown", "1"]).unwrap();
        for k in 1..=8 {
            let x = 500 + to * k / 8;
            display.xdotool(&[
                "mousemove",
                "--window",
                &player.window,
                &x.to_string(),
                "420",
            ]);
            std::thread::sleep(Duration::from_millis(100));
        }
        display.xdotool(&["mouseup", "1"]).unwrap();
    };
    drag(160);
    std::thread::sleep(Duration::from_millis(1500));
    player.key(&display, "Left");
    std::thread::sleep(Duration::from_millis(300));
    player.key(&display, "Right");
    std::thread::sleep(Duration::from_millis(300));
    drag(-80);
    wait_refined(&player, 1, 3, player.log().lines().count());
    let log = player.log();
    let passes = busy_intervals(&log, from);
    let mut ms: Vec<f64> = passes.iter().map(|p| p.interval).collect();
    ms.sort_by(f64::total_cmp);
    let percentile = |q: usize| ms[(ms.len() * q / 100).min(ms.len() - 1)];
    let slowest = |key: &dyn Fn(&BusyPass) -> f64| {
        let mut by: Vec<&BusyPass> = passes.iter().collect();
        by.sort_by(|a, b| key(b).total_cmp(&key(a)));
        by
    };
    let by_interval = slowest(&|p| p.interval);
    for p in by_interval.iter().take(6) {
        eprintln!("slow pass {:.1} ms: {}", p.interval, p.line);
    }
    let worst = by_interval[0];
    eprintln!(
        "{} busy passes: p50 {:.1} ms, p90 {:.1} ms, max {:.1} ms",
        ms.len(),
        percentile(50),
        percentile(90),
        worst.interval,
    );
    for kind in ["preview", "masks", "rows"] {
        assert!(
            passes.iter().any(|p| p.line.contains(kind)),
            "no pass drew {kind}"
        );
    }
    // What the player logged around a pass, to say where its time went.
    let around = |line: &str| {
        let lines: Vec<&str> = log.lines().collect();
        let pass = line.split(':').next().unwrap_or_default();
        if let Some(at) = lines
            .iter()
            .position(|l| l.starts_with(&format!("{pass}:")))
        {
            for l in &lines[at.saturating_sub(12)..(at + 3).min(lines.len())] {
                eprintln!("  {l}");
            }
        }
    };
    // The own work of every pass: those the frame budget paces, and the pass at rest, which
    // probes the pixel under the pointer (reading it back without waiting for the GPU, which
    // on lavapipe runs the copy behind eframe's paint: 101-110 ms when the pass waited).
    let by_own = slowest(&|p| p.own);
    let by_frame = slowest(&|p| p.frame_work);
    for (what, p, ms) in [
        ("own work", by_own[0], by_own[0].own),
        ("frame work", by_frame[0], by_frame[0].frame_work),
    ] {
        eprintln!("most {what} {ms:.1} ms: {}", p.line);
        if ms > 100.0 {
            around(&p.line);
        }
    }
    if worst.interval > 100.0 {
        around(&worst.line);
    }
    assert!(
        by_own[0].own <= 100.0,
        "a pass's own work took {:.1} ms: {}",
        by_own[0].own,
        by_own[0].line
    );
    // The whole frame on the UI thread, the player's pass and eframe's paint (egui's, sized by
    // the window): within 100 ms for all but one pass in 100, none over 200 ms. (The slowest CI
    // run so far: 75.5 ms, of which the pass before 41.3.)
    assert!(
        passes.iter().all(|p| p.frame_work.is_finite()),
        "eframe said no frame time"
    );
    let heavy = passes.iter().filter(|p| p.frame_work > 100.0).count();
    assert!(
        heavy * 100 <= passes.len() && by_frame[0].frame_work <= 200.0,
        "{heavy} of {} frames' work on the UI thread took over 100 ms, the most {:.1} ms: {}",
        passes.len(),
        by_frame[0].frame_work,
        by_frame[0].line
    );
    // The interval also holds the waits for the window's surface and the present, which
    // Xvfb and lavapipe's queue decide: nine passes in ten within 100 ms, none frozen.
    assert!(
        percentile(90) <= 100.0,
        "the busy passes' p90 interval is {:.1} ms",
        percentile(90)
    );
    assert!(
        worst.interval <= 250.0,
        "a pass took {:.1} ms: {}",
        worst.interval,
        worst.line
    );

    // At rest, refined: the app's screenshot is `slosh render` of the view, pixel for pixel.
    let shot = screenshot_against_render(&player, &display, dir.path(), &cache, 1, &[]);

    // A click on the surface reads it back (issue 28, item 5): a point on the true sphere of
    // step 1, within two spacings of the input particle it names.
    let centre = (
        shot.viewport.0 + shot.width / 2,
        shot.viewport.1 + shot.height / 2,
    );
    display.xdotool(&[
        "mousemove",
        "--window",
        &player.window,
        &centre.0.to_string(),
        &centre.1.to_string(),
    ]);
    display.xdotool(&["click", "1"]).unwrap();
    wait_for("the probe", Duration::from_secs(60), || {
        player.log().contains("probe step 1 ")
    });
    let log = player.log();
    let line = log
        .lines()
        .find(|l| l.starts_with("probe step 1 "))
        .unwrap();
    eprintln!("{line}");
    // The `k`-th word after `key`.
    let word_after_by = |key: &str, k: usize| {
        let words: Vec<&str> = line.split_whitespace().collect();
        let i = words.iter().position(|w| *w == key).unwrap();
        words[i + k].to_string()
    };
    let word_after = |key: &str| word_after_by(key, 1);
    let position: Vec<f64> = word_after("position")
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.join("truth.json")).unwrap()).unwrap();
    let surface = &truth["steps"][1]["surface"];
    let radius = surface["radius"].as_f64().unwrap();
    let from_centre = (0..3)
        .map(|a| (position[a] - surface["center"][a].as_f64().unwrap()).powi(2))
        .sum::<f64>()
        .sqrt();
    let spacing = truth["spacing"].as_f64().unwrap();
    assert!(
        (from_centre - radius).abs() < 0.1 * spacing,
        "the probe is {from_centre} from the centre of a sphere of radius {radius}"
    );
    let distance: f64 = word_after("at").parse().unwrap();
    assert!(
        distance < 2.0 * spacing,
        "{distance} from the nearest particle"
    );
    // The particle named by its index in the EnSight case, at its position there: as near.
    let input: usize = word_after("input").parse().unwrap();
    assert!(input < 300_000);
    let at: Vec<f64> = word_after_by("input", 2)
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let apart = (0..3)
        .map(|a| (at[a] - position[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        (apart - distance).abs() < 1e-4 * spacing,
        "input particle {input} is {apart} from the probe, the stored one {distance}"
    );
}

/// `slosh play CASE.case`: the raw case opens at once with every step on the timeline, steps
/// are baked as the player needs them into NAME.slosh beside the case (with the manifest once
/// every one is), and `slosh bake` of the case with the same settings afterwards keeps every
/// one of them.
#[test]
fn a_raw_case_plays_at_once_and_is_baked_beside_it() {
    if !tools() {
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let case = droplets_case(dir.path(), 3);
    let cache = case.with_file_name("droplets.slosh");
    let step_file = |i: usize| cache.join(format!("step-{i:05}.slc"));
    let display = Display::start();
    let player = Player::start(
        &display,
        &case,
        dir.path(),
        &["--fields", "pressure", "--field", "pressure"],
    );
    player.wait_title(&display, "step 0/2");
    player.key(&display, "End");
    player.wait_title(&display, "step 2/2");
    wait_for(
        "every step baked beside the case",
        Duration::from_secs(120),
        || (0..3).all(|i| step_file(i).exists()),
    );
    let log = player.log();
    assert!(!log.lines().any(|l| l.contains("failed step")), "{log}");
    // The bake that completed the series wrote its manifest: a whole, verified series.
    wait_for(
        "the manifest of the completed series",
        Duration::from_secs(30),
        || cache.join("manifest.json").exists(),
    );
    slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    drop(player);
    let stamps: Vec<_> = (0..3)
        .map(|i| std::fs::metadata(step_file(i)).unwrap().modified().unwrap())
        .collect();
    // `slosh bake` of the same case and settings into the player's directory.
    slosh(&[
        "bake",
        case.to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
        "--fields",
        "pressure",
        "--quiet",
    ]);
    let after: Vec<_> = (0..3)
        .map(|i| std::fs::metadata(step_file(i)).unwrap().modified().unwrap())
        .collect();
    assert_eq!(
        stamps, after,
        "slosh bake baked again what the player had baked"
    );
    slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
}
