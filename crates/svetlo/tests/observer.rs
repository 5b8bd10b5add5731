//! The pass observer (`Progress::observed`) of every method in the registry: it is called,
//! the samples it sees never decrease, and the last film it sees is the one the render
//! returns, so a preview of a finished render shows exactly the written image.

use std::sync::{Arc, Mutex};
use svetlo::film::{Film, Image};
use svetlo::integrator::{Progress, RenderSettings};

#[test]
fn every_method_shows_its_passes_and_ends_on_its_result() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let mut scene = svetlo::io::load_scene(&path, &[]).expect("the bundled Cornell box loads");
    scene.camera.width = 12;
    scene.camera.height = 12;
    let settings = RenderSettings { spp: 4, max_depth: 4, threads: 2, ..RenderSettings::from_scene(&scene) };
    for m in svetlo::methods::METHODS {
        type Seen = Mutex<Vec<(u32, Image)>>;
        let seen: Arc<Seen> = Arc::default();
        let log = seen.clone();
        let progress = Progress::observed(move |f: &Film| log.lock().unwrap().push((f.spp_done, f.image())));
        // Small maps, meshes and bootstraps: the observer, not the method, is under test.
        let spec = match m.name {
            "photon" => "photon:photons=2000,caustic-photons=500,gather=4",
            "radiosity" => "radiosity:element-size=1",
            "pssmlt" => "pssmlt:bootstrap=1000,chains=4",
            "mlt" => "mlt:bootstrap=1000,chains=4",
            n => n,
        };
        let integrator = svetlo::methods::by_name(spec).unwrap();
        let film = integrator.render(&scene, &settings, &progress).unwrap_or_else(|e| panic!("{}: {e}", m.name));
        let seen = seen.lock().unwrap();
        assert!(!seen.is_empty(), "{}: never observed", m.name);
        assert!(seen.windows(2).all(|w| w[0].0 <= w[1].0), "{}: samples went down", m.name);
        let (spp, last) = seen.last().unwrap();
        assert_eq!(*spp, film.spp_done, "{}", m.name);
        assert_eq!(last.data, film.image().data, "{}: the last film shown is not the result", m.name);
    }
}
