//! What the preview knows about the render(s) it shows: one slot per method, each with the
//! latest developed film and its error curve, shared by the render thread (through the
//! pass observer), the page connections and the tev stream. Every change bumps `version`
//! and wakes the readers, which send only the newest state (a slow page never queues frames).

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use svetlo::film::{compare::rel_mse, Film, Image};
use svetlo::integrator::{PassObserver, Progress};

/// The image layers every film has; a page can also choose the film's AOV layers, which follow
/// these in [`Info::layers`] and [`Frame::layers`].
pub const LAYERS: &[&str] = &["color", "variance"];

/// Largest share of the render's time the observer may spend developing films.
pub const WATCH_BUDGET: f64 = 0.02;

/// Most points kept per error curve (halved by dropping every other one when reached).
const MAX_CURVE: usize = 2048;

/// One developed state of a film: every layer, linear, at the film's size.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// In the order of [`Info::layers`]: [`LAYERS`], then the AOVs.
    pub layers: Vec<Image>,
}

impl Frame {
    pub fn develop(film: &Film) -> Frame {
        let mut layers = vec![film.image(), film.variance_image()];
        layers.extend(film.layer_images().into_iter().map(|(_, im)| im));
        Frame { width: film.width, height: film.height, spp: film.spp_done, layers }
    }
    pub fn color(&self) -> &Image {
        &self.layers[0]
    }
}

/// Estimated relMSE of a film from its own per-pixel variance: the mean over pixels and
/// channels of `(v / n) / (x^2 + 0.01)` (the variance of the pixel mean against the
/// reference-free stand-in for `r^2`). `None` when the method keeps no usable variance
/// (fewer than two samples per pixel, or light paths the per-pixel statistics do not see).
pub fn estimated_rel_mse(color: &Image, variance: &Image, spp: u32) -> Option<f64> {
    if spp < 2 || color.data.is_empty() {
        return None;
    }
    let mut sum = 0.0f64;
    let mut any_variance = false;
    for (x, v) in color.data.iter().zip(&variance.data) {
        for k in 0..3 {
            let (x, v) = (x[k] as f64, v[k] as f64);
            any_variance |= v > 0.0;
            sum += (v / spp as f64) / (x * x + 0.01);
        }
    }
    let lit = color.data.iter().any(|c| c.max_component() > 0.0);
    if lit && !any_variance {
        return None;
    }
    Some(sum / (3 * color.data.len()) as f64)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    Queued,
    Running,
    Done,
    Stopped,
    Failed,
}

impl SlotState {
    pub fn name(self) -> &'static str {
        match self {
            SlotState::Queued => "queued",
            SlotState::Running => "running",
            SlotState::Done => "done",
            SlotState::Stopped => "stopped",
            SlotState::Failed => "failed",
        }
    }
}

/// One method's render.
pub struct Slot {
    pub method: String,
    pub state: SlotState,
    pub frame: Option<Arc<Frame>>,
    /// Bumped with every new frame.
    pub frame_version: u64,
    pub started: Option<Instant>,
    /// Wall time of the render once it ended.
    pub elapsed: Option<f64>,
    pub time_limit: Option<f64>,
    pub progress: Option<Arc<Progress>>,
    /// (seconds since the start, relMSE) after each pass.
    pub curve: Vec<[f64; 2]>,
    pub written: Vec<String>,
    pub error: Option<String>,
}

impl Slot {
    fn new(method: &str) -> Self {
        Slot {
            method: method.to_string(),
            state: SlotState::Queued,
            frame: None,
            frame_version: 0,
            started: None,
            elapsed: None,
            time_limit: None,
            progress: None,
            curve: Vec::new(),
            written: Vec::new(),
            error: None,
        }
    }

    pub fn seconds(&self) -> f64 {
        self.elapsed.or_else(|| self.started.map(|s| s.elapsed().as_secs_f64())).unwrap_or(0.0)
    }

    /// Fraction done and seconds left, from the render's progress counters and time budget.
    pub fn fraction_and_eta(&self) -> (f64, Option<f64>) {
        if self.state != SlotState::Running {
            return (if matches!(self.state, SlotState::Done) { 1.0 } else { self.progress.as_ref().map_or(0.0, |p| p.fraction()) }, None);
        }
        let t = self.seconds();
        let mut f = self.progress.as_ref().map_or(0.0, |p| p.fraction());
        let mut eta = (f > 0.0).then(|| t * (1.0 - f) / f);
        if let Some(limit) = self.time_limit {
            f = f.max(t / limit);
            let left = (limit - t).max(0.0);
            eta = Some(eta.map_or(left, |e| e.min(left)));
        }
        (f.clamp(0.0, 1.0), eta)
    }
}

/// What a page may change (serve mode), and what the current run uses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Config {
    pub methods: Vec<String>,
    pub spp: u32,
    pub max_depth: i32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// `svetlo render --preview`: one render; the page can stop it, not change it.
    Render,
    /// `svetlo serve`: the page can restart with other methods and settings.
    Serve,
}

pub struct State {
    pub version: u64,
    /// Bumped by every (re)start; frames of an older run are ignored.
    pub run: u64,
    pub config: Config,
    pub slots: Vec<Slot>,
    /// A restart the page asked for, taken by the driver when the current render returns.
    pub pending: Option<Config>,
    /// The page asked to stop: the methods still queued are skipped.
    pub stop: bool,
    /// The process is ending: pages get the last state, then a close.
    pub shutdown: bool,
    pub message: String,
}

/// Fixed facts about the session.
pub struct Info {
    pub mode: Mode,
    pub scene: String,
    pub reference: Option<Image>,
    /// The layers a page can choose: [`LAYERS`], then the render's AOVs by name.
    pub layers: Vec<String>,
}

impl Info {
    pub fn new(mode: Mode, scene: String, reference: Option<Image>, aovs: &[String]) -> Info {
        let layers = LAYERS.iter().map(|l| l.to_string()).chain(aovs.iter().cloned()).collect();
        Info { mode, scene, reference, layers }
    }
}

pub struct Session {
    pub info: Info,
    state: Mutex<State>,
    changed: Condvar,
}

impl Session {
    pub fn new(info: Info, config: Config) -> Arc<Session> {
        let slots = config.methods.iter().map(|m| Slot::new(m)).collect();
        let state = State { version: 1, run: 1, config, slots, pending: None, stop: false, shutdown: false, message: String::new() };
        Arc::new(Session { info, state: Mutex::new(state), changed: Condvar::new() })
    }

    /// The state, even if a thread panicked while holding it (the data stays consistent
    /// enough to show).
    pub fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Change the state and wake everyone who shows it.
    pub fn update<R>(&self, f: impl FnOnce(&mut State) -> R) -> R {
        let mut s = self.lock();
        let r = f(&mut s);
        s.version += 1;
        drop(s);
        self.changed.notify_all();
        r
    }

    /// Wake the waiters without a change (a connection closed, a page chose another layer).
    pub fn poke(&self) {
        self.changed.notify_all();
    }

    /// Wait until the version differs from `seen`, or `timeout` passes.
    pub fn wait_change(&self, seen: u64, timeout: Duration) -> MutexGuard<'_, State> {
        let s = self.lock();
        let (s, _) = self.changed.wait_timeout_while(s, timeout, |s| s.version == seen).unwrap_or_else(|e| e.into_inner());
        s
    }

    /// Start a new run: fresh slots for `config`'s methods. Returns the run number.
    pub fn begin_run(&self, config: Config) -> u64 {
        self.update(|s| {
            s.run += 1;
            s.slots = config.methods.iter().map(|m| Slot::new(m)).collect();
            s.config = config;
            s.stop = false;
            s.message.clear();
            s.run
        })
    }

    /// Whether the current run should not start another method.
    pub fn interrupted(&self) -> bool {
        let s = self.lock();
        s.stop || s.shutdown || s.pending.is_some()
    }

    /// Method `slot` of `run` starts, with this progress (the page's stop button cancels it).
    pub fn start_slot(&self, run: u64, slot: usize, progress: Arc<Progress>, time_limit: Option<Duration>) {
        self.update(|s| {
            if let (true, Some(sl)) = (s.run == run, s.slots.get_mut(slot)) {
                sl.state = SlotState::Running;
                sl.started = Some(Instant::now());
                sl.progress = Some(progress);
                sl.time_limit = time_limit.map(|t| t.as_secs_f64());
            }
        });
    }

    /// The pass observer of method `slot` of `run` (see [`Watcher`]).
    pub fn observer(self: &Arc<Self>, run: u64, slot: usize, planned_spp: u32) -> Watcher {
        Watcher { session: self.clone(), run, slot, planned_spp, last: Mutex::new(None) }
    }

    /// A new frame for method `slot` of `run`, with its point on the error curve.
    pub fn publish(&self, run: u64, slot: usize, frame: Frame) {
        let relmse = match &self.info.reference {
            Some(r) => rel_mse(frame.color(), r).ok(),
            None => estimated_rel_mse(frame.color(), &frame.layers[1], frame.spp),
        };
        self.update(|s| {
            if s.run != run {
                return;
            }
            let Some(sl) = s.slots.get_mut(slot) else { return };
            if let Some(e) = relmse.filter(|e| e.is_finite()) {
                let t = sl.seconds();
                if sl.curve.last().is_none_or(|p| p[0] < t) {
                    if sl.curve.len() >= MAX_CURVE {
                        sl.curve = sl.curve.iter().step_by(2).copied().collect();
                    }
                    sl.curve.push([t, e]);
                }
            }
            sl.frame = Some(Arc::new(frame));
            sl.frame_version += 1;
        });
    }

    /// Method `slot` of `run` returned its film (published as the last frame).
    pub fn finish_slot(&self, run: u64, slot: usize, film: Option<&Film>, written: Vec<String>, error: Option<String>) {
        let elapsed = self.lock().slots.get(slot).map(|s| s.seconds());
        if let Some(f) = film {
            self.publish(run, slot, Frame::develop(f));
        }
        self.update(|s| {
            if s.run != run {
                return;
            }
            let Some(sl) = s.slots.get_mut(slot) else { return };
            let cancelled = sl.progress.as_ref().is_some_and(|p| p.cancelled());
            sl.state = if error.is_some() {
                SlotState::Failed
            } else if cancelled {
                SlotState::Stopped
            } else {
                SlotState::Done
            };
            sl.elapsed = elapsed;
            sl.written = written;
            if let Some(e) = &error {
                s.message = format!("{}: {e}", sl.method);
            }
            sl.error = error;
        });
    }

    /// Stop the current render (keeping its samples) and skip the methods still queued.
    pub fn stop(&self) {
        self.update(|s| {
            s.stop = true;
            cancel_running(s);
            s.message = "stopped: the samples done are kept".into();
        });
    }

    /// Restart with `config` (serve mode): cancels the current render.
    pub fn restart(&self, config: Config) {
        self.update(|s| {
            s.pending = Some(config);
            cancel_running(s);
        });
    }

    /// The process ends: cancel what runs, and let the pages have the last state.
    pub fn shut_down(&self) {
        self.update(|s| {
            s.shutdown = true;
            cancel_running(s);
        });
    }

    /// Report something to every page.
    pub fn say(&self, message: String) {
        self.update(|s| s.message = message);
    }
}

fn cancel_running(s: &mut State) {
    for sl in &s.slots {
        if let Some(p) = &sl.progress {
            p.cancel.store(true, std::sync::atomic::Ordering::SeqCst);
        }
    }
}

/// A JSON string literal.
pub fn json_str(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => o.push_str(&format!("\\u{:04x}", c as u32)),
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// A JSON number (`null` for what JSON cannot say).
fn json_num(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        "null".into()
    }
}

/// The first message of a connection: what does not change.
pub fn hello_json(info: &Info) -> String {
    let methods: Vec<String> =
        svetlo::methods::METHODS.iter().map(|m| format!("{{\"name\":{},\"summary\":{}}}", json_str(m.name), json_str(m.summary))).collect();
    let layers: Vec<String> = info.layers.iter().map(|l| json_str(l)).collect();
    format!(
        "{{\"type\":\"hello\",\"mode\":{},\"scene\":{},\"reference\":{},\"methods\":[{}],\"layers\":[{}]}}",
        json_str(if info.mode == Mode::Serve { "serve" } else { "render" }),
        json_str(&info.scene),
        info.reference.is_some(),
        methods.join(","),
        layers.join(",")
    )
}

/// The state as the page reads it.
pub fn status_json(s: &State) -> String {
    let slots: Vec<String> = s
        .slots
        .iter()
        .map(|sl| {
            let (fraction, eta) = sl.fraction_and_eta();
            let t = sl.seconds();
            let (spp, w, h) = sl.frame.as_ref().map_or((0, 0, 0), |f| (f.spp, f.width, f.height));
            let curve: Vec<String> = sl.curve.iter().map(|p| format!("[{},{}]", json_num(p[0]), json_num(p[1]))).collect();
            let written: Vec<String> = sl.written.iter().map(|w| json_str(w)).collect();
            let rate = if t > 0.0 { spp as f64 * w as f64 * h as f64 / t } else { 0.0 };
            format!(
                "{{\"method\":{},\"state\":{},\"spp\":{spp},\"fraction\":{},\"elapsed\":{},\"eta\":{},\"samples_per_s\":{},\"relmse\":{},\"curve\":[{}],\"written\":[{}],\"error\":{}}}",
                json_str(&sl.method),
                json_str(sl.state.name()),
                json_num(fraction),
                json_num(t),
                eta.map_or("null".into(), json_num),
                json_num(rate),
                sl.curve.last().map_or("null".into(), |p| json_num(p[1])),
                curve.join(","),
                written.join(","),
                sl.error.as_deref().map_or("null".into(), json_str),
            )
        })
        .collect();
    let methods: Vec<String> = s.config.methods.iter().map(|m| json_str(m)).collect();
    let running = s.slots.iter().any(|sl| matches!(sl.state, SlotState::Running | SlotState::Queued)) && !s.stop;
    format!(
        "{{\"type\":\"status\",\"run\":{},\"running\":{running},\"shutdown\":{},\"message\":{},\"config\":{{\"methods\":[{}],\"spp\":{},\"max_depth\":{}}},\"slots\":[{}]}}",
        s.run,
        s.shutdown,
        json_str(&s.message),
        methods.join(","),
        s.config.spp,
        s.config.max_depth,
        slots.join(",")
    )
}

/// Header of a binary frame message: magic, slot, layer, size, spp, run; then the layer as
/// half floats, RGB interleaved, rows from the top (little-endian throughout).
pub const FRAME_HEADER: usize = 24;

pub fn encode_frame(frame: &Frame, slot: usize, layer: usize, run: u64) -> Vec<u8> {
    let img = &frame.layers[layer.min(frame.layers.len() - 1)];
    let mut out = Vec::with_capacity(FRAME_HEADER + img.data.len() * 6);
    out.extend_from_slice(b"SVF1");
    out.push(slot as u8);
    out.push(layer as u8);
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(&frame.width.to_le_bytes());
    out.extend_from_slice(&frame.height.to_le_bytes());
    out.extend_from_slice(&frame.spp.to_le_bytes());
    out.extend_from_slice(&(run as u32).to_le_bytes());
    out.resize(FRAME_HEADER + img.data.len() * 6, 0);
    for (dst, c) in out[FRAME_HEADER..].chunks_exact_mut(6).zip(&img.data) {
        for k in 0..3 {
            dst[2 * k..2 * k + 2].copy_from_slice(&f16_bits(c[k]).to_le_bytes());
        }
    }
    out
}

/// IEEE half-precision bits of `x`, rounded to nearest even (overflow to infinity, tiny
/// values to subnormals or zero, NaN stays NaN).
pub fn f16_bits(x: f32) -> u16 {
    let b = x.to_bits();
    let sign = ((b >> 16) & 0x8000) as u16;
    let exp = ((b >> 23) & 0xff) as i32;
    let man = b & 0x7f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if man != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    let round = |r: u32, rem: u32, half: u32| if rem > half || (rem == half && r & 1 == 1) { r + 1 } else { r };
    if e <= 0 {
        if e < -10 {
            return sign;
        }
        let m = man | 0x80_0000;
        let shift = (14 - e) as u32;
        let r = round(m >> shift, m & ((1 << shift) - 1), 1 << (shift - 1));
        return sign | r as u16;
    }
    // A carry out of the mantissa steps the exponent, up to infinity: still the right bits.
    sign | round(((e as u32) << 10) | (man >> 13), man & 0x1fff, 0x1000) as u16
}

/// Watches one method's render: develops the film (on the render thread: two passes over
/// the pixels), measures its error and publishes it. Passes that come sooner after the last
/// development than [`WATCH_BUDGET`] allows are declined before the render assembles their
/// film (only on large films: at 512² a development takes milliseconds), except the one that
/// completes the planned spp.
pub struct Watcher {
    session: Arc<Session>,
    run: u64,
    slot: usize,
    planned_spp: u32,
    /// When the last development started and what it cost.
    last: Mutex<Option<(Instant, Duration)>>,
}

impl PassObserver for Watcher {
    fn wants(&self, spp_done: u32) -> bool {
        let previous = *self.last.lock().unwrap_or_else(|e| e.into_inner());
        match previous {
            Some((at, cost)) => spp_done == self.planned_spp || at.elapsed().as_secs_f64() * WATCH_BUDGET >= cost.as_secs_f64(),
            None => true,
        }
    }
    fn show(&self, film: &Film) {
        let start = Instant::now();
        self.session.publish(self.run, self.slot, Frame::develop(film));
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some((start, start.elapsed()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use svetlo::Rgb;

    fn f16_value(h: u16) -> f32 {
        let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
        let e = ((h >> 10) & 0x1f) as i32;
        let m = (h & 0x3ff) as f32;
        sign * match e {
            0 => m * 2f32.powi(-24),
            31 if m == 0.0 => f32::INFINITY,
            31 => f32::NAN,
            _ => (1.0 + m / 1024.0) * 2f32.powi(e - 15),
        }
    }

    #[test]
    fn half_floats_round_correctly() {
        assert_eq!(f16_bits(1.0), 0x3c00);
        assert_eq!(f16_bits(-2.0), 0xc000);
        assert_eq!(f16_bits(0.1), 0x2e66);
        assert_eq!(f16_bits(65504.0), 0x7bff);
        assert_eq!(f16_bits(65520.0), 0x7c00, "rounds up to infinity");
        assert_eq!(f16_bits(1e9), 0x7c00);
        assert_eq!(f16_bits(f32::INFINITY), 0x7c00);
        assert_eq!(f16_bits(f32::NAN) & 0x7e00, 0x7e00);
        assert_eq!(f16_bits(2f32.powi(-24)), 0x0001);
        assert_eq!(f16_bits(2f32.powi(-25)), 0x0000, "tie to even");
        assert_eq!(f16_bits(1.5 * 2f32.powi(-25)), 0x0001);
        assert_eq!(f16_bits(1e-10), 0);
        // Every finite half survives the round trip, and halfway points go to the even one.
        for h in 0..=0xffffu16 {
            let v = f16_value(h);
            if v.is_finite() {
                assert_eq!(f16_bits(v), if h == 0x8000 { 0x8000 } else { h }, "{h:#x}");
            }
        }
        assert_eq!(f16_bits(1.0 + 2f32.powi(-11)), 0x3c00);
        assert_eq!(f16_bits(1.0 + 3.0 * 2f32.powi(-11)), 0x3c02);
    }

    #[test]
    fn frame_messages_have_the_documented_layout() {
        let img = Image::new(2, 1, vec![Rgb::splat(1.0), Rgb::new(0.0, -2.0, 65504.0)]);
        let var = Image::new(2, 1, vec![Rgb::BLACK; 2]);
        let f = Frame { width: 2, height: 1, spp: 7, layers: vec![img, var] };
        let m = encode_frame(&f, 1, 0, 3);
        assert_eq!(m.len(), FRAME_HEADER + 2 * 6);
        assert_eq!(&m[..6], b"SVF1\x01\x00");
        assert_eq!(u32::from_le_bytes(m[8..12].try_into().unwrap()), 2);
        assert_eq!(u32::from_le_bytes(m[16..20].try_into().unwrap()), 7);
        assert_eq!(u32::from_le_bytes(m[20..24].try_into().unwrap()), 3);
        let half = |i: usize| u16::from_le_bytes([m[FRAME_HEADER + 2 * i], m[FRAME_HEADER + 2 * i + 1]]);
        assert_eq!([half(0), half(3), half(4), half(5)], [0x3c00, 0, 0xc000, 0x7bff]);
    }

    #[test]
    fn error_estimate_from_variance() {
        // Mean 1 with per-sample variance 0.04 over 4 samples: (0.04 / 4) / 1.01 per channel.
        let c = Image::new(1, 1, vec![Rgb::splat(1.0)]);
        let v = Image::new(1, 1, vec![Rgb::splat(0.04)]);
        let e = estimated_rel_mse(&c, &v, 4).unwrap();
        assert!((e - 0.01 / 1.01).abs() < 1e-9, "{e}");
        assert_eq!(estimated_rel_mse(&c, &v, 1), None, "one sample has no variance");
        assert_eq!(estimated_rel_mse(&c, &Image::new(1, 1, vec![Rgb::BLACK]), 4), None, "lit but no variance kept");
    }

    /// A run as the page sees it: queued, running with an error curve, then done.
    #[test]
    fn session_states_reach_the_status() {
        let info = Info::new(Mode::Serve, "s".into(), None, &[]);
        let s = Session::new(info, Config { methods: vec!["path".into(), "bdpt".into()], spp: 4, max_depth: 3 });
        let run = s.begin_run(Config { methods: vec!["path".into()], spp: 4, max_depth: 3 });
        assert!(status_json(&s.lock()).contains("\"state\":\"queued\""));
        let p = Arc::new(Progress::new());
        s.start_slot(run, 0, p.clone(), None);
        let mut film = Film::new(2, 1, svetlo::film::Filter::Box);
        for (i, v) in [1.0f32, 1.2, 0.8, 1.1].iter().enumerate() {
            film.add_sample(glam::Vec2::new(0.5 + (i % 2) as f32, 0.5), Rgb::splat(*v));
        }
        film.spp_done = 2;
        std::thread::sleep(Duration::from_millis(2));
        s.publish(run, 0, Frame::develop(&film));
        s.publish(run + 1, 0, Frame::develop(&film)); // a stale run: ignored
        let st = status_json(&s.lock());
        assert!(st.contains("\"state\":\"running\"") && st.contains("\"spp\":2") && st.contains("\"curve\":[["), "{st}");
        assert_eq!(s.lock().slots[0].frame_version, 1);
        s.stop();
        assert!(p.cancelled(), "stop cancels the running render");
        s.finish_slot(run, 0, Some(&film), vec!["a.exr".into()], None);
        let st = status_json(&s.lock());
        assert!(st.contains("\"state\":\"stopped\"") && st.contains("\"written\":[\"a.exr\"]") && st.contains("\"running\":false"), "{st}");
    }

    #[test]
    fn json_escapes() {
        assert_eq!(json_str("a\"b\\c\n"), "\"a\\\"b\\\\c\\u000a\"");
        assert_eq!(json_num(f64::NAN), "null");
    }
}
