//! Renders split into ranges of passes (nodes of the pass tree), each rendered apart, sent as
//! bytes and merged: the local render's film bit for bit (beauty, variance, AOV layers), for
//! every pass-separable method, any number of chunks and any thread count. Scenes are the
//! repository's own (`scenes/`).

use std::path::Path;
use std::sync::Arc;
use svetlo::film::raw::PartialFilm;
use svetlo::film::{Film, Image};
use svetlo::integrator::passes::{chunk_nodes, pass_plan};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::scene::Scene;

fn scene(name: &str, w: u32, h: u32) -> Scene {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
    let mut s = svetlo::io::load_scene(&p, &[]).expect("bundled scene");
    s.camera.width = w;
    s.camera.height = h;
    s
}

fn bits(img: &Image) -> Vec<u32> {
    img.data.iter().flat_map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()]).collect()
}

/// The film of `spec` merged from `chunks` nodes, each rendered with `threads` threads and
/// passed through bytes (in reverse order, to show that arrival order does not matter).
fn distributed(spec: &str, scene: &Scene, s: &RenderSettings, chunks: usize, threads: usize) -> Film {
    let plan = pass_plan(s.spp, scene.camera.width as u64 * scene.camera.height as u64);
    let nodes = chunk_nodes(&plan, chunks);
    let mut parts = Vec::new();
    for r in nodes.into_iter().rev() {
        let st = RenderSettings { threads, ..s.clone() };
        let part = svetlo::methods::render_passes(spec, scene, &st, r, &[], &Progress::new()).unwrap_or_else(|e| panic!("{spec}: {e}"));
        parts.push(PartialFilm::from_bytes(&part.to_bytes()).expect("round trip"));
    }
    PartialFilm::merge(parts).expect("merge")
}

fn assert_same(a: &Film, b: &Film, what: &str) {
    assert_eq!(a.spp_done, b.spp_done, "{what}: spp");
    assert!(bits(&a.image()) == bits(&b.image()), "{what}: images differ");
    assert!(bits(&a.variance_image()) == bits(&b.variance_image()), "{what}: variance images differ");
    let (la, lb) = (a.layer_images(), b.layer_images());
    assert_eq!(la.len(), lb.len());
    for ((na, ia), (_, ib)) in la.iter().zip(&lb) {
        assert!(bits(ia) == bits(ib), "{what}: layer {na} differs");
    }
}

#[test]
fn merged_ranges_are_the_local_render_bit_for_bit() {
    let cbox = scene("cornell-box.xml", 20, 16);
    // 37 spp on 320 pixels: passes 1, 2, 4, then 4s and a 2 (eleven passes, a ragged tree).
    let s = RenderSettings { spp: 37, max_depth: 5, seed: 7, threads: 2, ..RenderSettings::from_scene(&cbox) };
    for spec in [
        "path",
        "path:simd=false",
        "light",
        "bdpt",
        "direct",
        "whitted",
        "distributed",
        "photon:photons=2000,caustic-photons=500,gather=4",
        "radiosity:element-size=1",
    ] {
        let local = svetlo::methods::by_name(spec).unwrap().render(&cbox, &s, &Progress::new()).unwrap();
        assert!(local.image().mean().max_component() > 0.0, "{spec}: black image");
        for (chunks, threads) in [(1, 1), (3, 1), (4, 2), (100, 2)] {
            assert_same(&local, &distributed(spec, &cbox, &s, chunks, threads), &format!("{spec}, {chunks} chunks, {threads} threads"));
        }
    }
}

#[test]
fn aov_layers_and_filters_merge_bit_for_bit() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/caustic.xml");
    let sc = svetlo::io::load_scene(&p, &[("res".into(), "24".into())]).expect("scenes/caustic.xml");
    let list = vec![("caustic".to_string(), "C D S+ L".to_string()), ("d1".to_string(), "C D [LB]".to_string())];
    let mut set = svetlo::lpe::AovSet::compile(&list, None).expect("expressions");
    assert!(set.bind(&sc).is_empty());
    for filter in [svetlo::film::Filter::Box, svetlo::film::Filter::Gaussian { stddev: 0.5 }] {
        let s = RenderSettings { spp: 21, max_depth: 6, seed: 3, threads: 2, filter, lpe: Some(Arc::new(set.clone())), ..Default::default() };
        for spec in ["path", "bdpt"] {
            let local = svetlo::methods::by_name(spec).unwrap().render(&sc, &s, &Progress::new()).unwrap();
            assert_eq!(local.layer_names().len(), 2);
            assert_same(&local, &distributed(spec, &sc, &s, 3, 2), &format!("{spec} with AOVs, {filter:?}"));
        }
    }
}

/// A Metropolis render split by chain blocks: one bootstrap (through bytes) shared by every
/// node, nodes rendered with `threads` threads, merged.
fn distributed_chains(spec: &str, scene: &Scene, s: &RenderSettings, chunks: usize, threads: usize) -> Film {
    assert_eq!(svetlo::methods::shared_units(spec).unwrap(), 1);
    let boot = svetlo::methods::shared_batch(spec, scene, s, 0..1, &Progress::new()).expect("bootstrap");
    let plan = svetlo::methods::unit_plan(spec, scene, s).expect("plan");
    let mut parts = Vec::new();
    for r in chunk_nodes(&plan, chunks).into_iter().rev() {
        let st = RenderSettings { threads, ..s.clone() };
        let part = svetlo::methods::render_passes(spec, scene, &st, r, &[&boot], &Progress::new()).unwrap_or_else(|e| panic!("{spec}: {e}"));
        parts.push(PartialFilm::from_bytes(&part.to_bytes()).expect("round trip"));
    }
    PartialFilm::merge(parts).expect("merge")
}

#[test]
fn metropolis_chain_blocks_merge_into_the_local_render_bit_for_bit() {
    let cbox = scene("cornell-box.xml", 12, 10);
    let s = RenderSettings { spp: 6, max_depth: 5, seed: 3, threads: 2, ..RenderSettings::from_scene(&cbox) };
    // 40 chains: blocks of 16, 16 and 8 chains.
    for spec in ["pssmlt:chains=40,bootstrap=3000", "pssmlt:chains=40,bootstrap=3000,target=path", "mlt:chains=40,bootstrap=2000"] {
        let plan = svetlo::methods::unit_plan(spec, &cbox, &s).unwrap();
        assert_eq!(plan, [(0, 16), (16, 16), (32, 8)], "{spec}");
        let local = svetlo::methods::by_name(spec).unwrap().render(&cbox, &s, &Progress::new()).unwrap();
        assert!(local.image().data.iter().any(|c| c.r > 0.0), "{spec}: black");
        for (chunks, threads) in [(1, 1), (2, 2), (3, 1), (8, 2)] {
            assert_same(&distributed_chains(spec, &cbox, &s, chunks, threads), &local, &format!("{spec}, {chunks} chunks, {threads} threads"));
        }
    }
    // The bootstrap is checked: malformed bytes, or one of another seed, are refused.
    let spec = "pssmlt:chains=20,bootstrap=500";
    let boot = svetlo::methods::shared_batch(spec, &cbox, &s, 0..1, &Progress::new()).unwrap();
    for cut in [0, 8, 63, boot.len() - 1] {
        assert!(svetlo::methods::render_passes(spec, &cbox, &s, 0..2, &[&boot[..cut]], &Progress::new()).is_err(), "cut at {cut}");
    }
    let other = RenderSettings { seed: 4, ..s.clone() };
    let e = svetlo::methods::render_passes(spec, &cbox, &other, 0..2, &[&boot], &Progress::new()).unwrap_err();
    assert!(e.to_string().contains("seed"), "{e}");
    assert!(svetlo::methods::render_passes(spec, &cbox, &s, 1..3, &[&boot], &Progress::new()).is_err(), "2 blocks: 1..3 is out of range");
}

#[test]
fn ranges_that_are_not_tree_nodes_and_unseparable_methods_are_refused() {
    let cbox = scene("cornell-box.xml", 8, 8);
    let s = RenderSettings { spp: 10, ..RenderSettings::from_scene(&cbox) };
    // 10 spp: ten passes of 1; 1..3 straddles a split of the tree (0..2 | 2..4).
    let e = svetlo::methods::render_passes("path", &cbox, &s, 1..3, &[], &Progress::new()).unwrap_err();
    assert!(e.to_string().contains("not a node"), "{e}");
    for spec in ["sppm", "zbuffer"] {
        let e = svetlo::methods::render_passes(spec, &cbox, &s, 0..4, &[], &Progress::new()).unwrap_err();
        assert!(e.to_string().contains("not a sum of independent"), "{spec}: {e}");
    }
    let timed = RenderSettings { time_limit: Some(std::time::Duration::from_secs(1)), ..s.clone() };
    assert!(svetlo::methods::render_passes("path", &cbox, &timed, 0..4, &[], &Progress::new()).is_err());
    // Parts that leave a pass out, or come from different renders, do not merge.
    let a = svetlo::methods::render_passes("path", &cbox, &s, 0..2, &[], &Progress::new()).unwrap();
    let b = svetlo::methods::render_passes("path", &cbox, &s, 2..3, &[], &Progress::new()).unwrap();
    assert!(PartialFilm::merge(vec![a.clone(), b]).is_err(), "pass 3 missing");
    let other = scene("cornell-box.xml", 9, 8);
    let c = svetlo::methods::render_passes("path", &other, &s, 2..4, &[], &Progress::new()).unwrap();
    assert!(PartialFilm::merge(vec![a, c]).is_err(), "different film sizes");
}

#[test]
fn malformed_bytes_are_errors() {
    let cbox = scene("cornell-box.xml", 6, 5);
    let s = RenderSettings { spp: 3, ..RenderSettings::from_scene(&cbox) };
    let part = svetlo::methods::render_passes("bdpt", &cbox, &s, 0..2, &[], &Progress::new()).unwrap();
    let bytes = part.to_bytes();
    for cut in [0, 7, 8, 20, bytes.len() / 2, bytes.len() - 1] {
        assert!(PartialFilm::from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(PartialFilm::from_bytes(&longer).is_err());
    // A header announcing a huge film is refused before anything is allocated.
    let mut huge = bytes.clone();
    huge[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
    huge[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(PartialFilm::from_bytes(&huge).is_err());
    let back = PartialFilm::from_bytes(&bytes).unwrap();
    assert_eq!(back.passes, 0..2);
    assert!(bits(&back.film.image()) == bits(&part.film.image()));
}

/// An SPPM render advanced in `blocks` row blocks from `batches` photon batches per
/// iteration, every state passed through bytes between iterations, the blocks developed
/// together (in reverse order).
fn sppm_in_rows(sppm: &svetlo::integrator::photon::Sppm, sc: &Scene, s: &RenderSettings, blocks: u32, batches: u64, threads: usize) -> Film {
    use svetlo::integrator::photon::SppmRows;
    let st = RenderSettings { threads, ..s.clone() };
    let (h, per) = (sc.camera.height, sppm.photons_per_iteration(sc));
    let mut states: Vec<SppmRows> = (0..blocks).map(|b| sppm.start_rows(sc, &st, b * h / blocks..(b + 1) * h / blocks).unwrap()).collect();
    for it in 0..s.spp {
        let cuts: Vec<u64> = (0..=batches).map(|k| k * per / batches).collect();
        let photons: Vec<Vec<u8>> = cuts.windows(2).map(|c| sppm.photon_batch(sc, &st, it, c[0]..c[1]).unwrap()).collect();
        let refs: Vec<&[u8]> = photons.iter().map(|b| b.as_slice()).collect();
        for state in states.iter_mut() {
            // Through bytes, as between iterations on a cluster.
            let mut back = SppmRows::from_bytes(&state.to_bytes()).unwrap();
            sppm.iterate_rows(sc, &st, &mut back, &refs).unwrap();
            *state = back;
        }
    }
    states.reverse();
    sppm.develop_rows(sc, &st, states).unwrap()
}

#[test]
fn sppm_in_row_blocks_from_photon_batches_is_the_local_render_bit_for_bit() {
    use svetlo::integrator::photon::{Sppm, SppmOptions, SppmRows};
    let cbox = scene("cornell-box.xml", 14, 11);
    let s = RenderSettings { spp: 4, max_depth: 6, seed: 2, threads: 2, ..RenderSettings::from_scene(&cbox) };
    let sppm = Sppm { options: SppmOptions { photons: Some(3000), ..Default::default() } };
    let local = svetlo::integrator::Integrator::render(&sppm, &cbox, &s, &Progress::new()).unwrap();
    assert!(local.image().data.iter().any(|c| c.r > 0.0));
    for (blocks, batches, threads) in [(1, 1, 1), (2, 3, 2), (11, 2, 1)] {
        let film = sppm_in_rows(&sppm, &cbox, &s, blocks, batches, threads);
        assert_same(&film, &local, &format!("sppm: {blocks} row blocks, {batches} photon batches, {threads} threads"));
    }
    // Rows that leave a gap, states of another render and malformed bytes are refused.
    let a = sppm.start_rows(&cbox, &s, 0..5).unwrap();
    assert!(sppm.develop_rows(&cbox, &s, vec![a.clone()]).is_err());
    let bytes = a.to_bytes();
    for cut in [0, 8, 27, 31, bytes.len() - 1] {
        assert!(SppmRows::from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    // A header asking for more layers than the bytes hold.
    let mut layered = bytes.clone();
    layered[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(SppmRows::from_bytes(&layered).is_err(), "layers in the header");
    let mut done = a.clone();
    let four = RenderSettings { spp: 0, ..s.clone() };
    assert!(sppm.iterate_rows(&cbox, &four, &mut done, &[]).is_err(), "no iteration left");
    assert!(sppm.iterate_rows(&cbox, &s, &mut done, &[b"SVLPHOT1\x01"]).is_err(), "malformed photons");
    assert!(sppm.start_rows(&cbox, &s, 5..12).is_err());
}

#[test]
fn sppm_aov_layers_in_row_blocks_are_the_local_render_bit_for_bit() {
    use svetlo::integrator::photon::{Sppm, SppmOptions};
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/caustic.xml");
    let sc = svetlo::io::load_scene(&p, &[("res".into(), "12".into())]).expect("scenes/caustic.xml");
    let list = vec![("caustic".to_string(), "C D S+ L".to_string()), ("d1".to_string(), "C D [LB]".to_string())];
    let mut set = svetlo::lpe::AovSet::compile(&list, None).expect("expressions");
    assert!(set.bind(&sc).is_empty());
    let s = RenderSettings { spp: 3, max_depth: 6, seed: 4, threads: 2, filter: svetlo::film::Filter::Box, lpe: Some(Arc::new(set)), ..Default::default() };
    let sppm = Sppm { options: SppmOptions { photons: Some(3000), ..Default::default() } };
    let local = svetlo::integrator::Integrator::render(&sppm, &sc, &s, &Progress::new()).unwrap();
    assert_eq!(local.layer_names().len(), 2);
    assert!(local.layer_images().iter().all(|(_, img)| img.data.iter().any(|c| c.r > 0.0)), "every layer has light");
    for (blocks, batches, threads) in [(1, 1, 1), (3, 2, 2)] {
        let film = sppm_in_rows(&sppm, &sc, &s, blocks, batches, threads);
        assert_same(&film, &local, &format!("sppm with AOVs: {blocks} row blocks, {batches} photon batches, {threads} threads"));
    }
    // A state without the layers is of another render.
    let plain = RenderSettings { lpe: None, ..s.clone() };
    let mut st = sppm.start_rows(&sc, &plain, 0..4).unwrap();
    assert!(sppm.iterate_rows(&sc, &s, &mut st, &[]).is_err(), "state without layers");
    assert!(sppm.develop_rows(&sc, &s, vec![sppm.start_rows(&sc, &plain, 0..sc.camera.height).unwrap()]).is_err());
}

#[test]
fn photon_maps_from_batches_traced_apart_are_the_local_render_bit_for_bit() {
    let cbox = scene("cornell-box.xml", 12, 10);
    let s = RenderSettings { spp: 5, max_depth: 6, seed: 9, threads: 2, ..RenderSettings::from_scene(&cbox) };
    let spec = "photon:photons=3000,caustic-photons=1000,gather=4,precompute=3";
    let local = svetlo::methods::by_name(spec).unwrap().render(&cbox, &s, &Progress::new()).unwrap();
    let paths = svetlo::methods::shared_units(spec).unwrap();
    assert_eq!(paths, 4000);
    let plan = pass_plan(s.spp, 120);
    // Batch cuts inside the global pass, at its end and inside the caustic pass.
    for cuts in [vec![0, 4000], vec![0, 1234, 3000, 3500, 4000], vec![0, 2999, 3001, 4000]] {
        let batches: Vec<Vec<u8>> = cuts.windows(2).map(|c| svetlo::methods::shared_batch(spec, &cbox, &s, c[0]..c[1], &Progress::new()).unwrap()).collect();
        let refs: Vec<&[u8]> = batches.iter().map(|b| b.as_slice()).collect();
        let parts = chunk_nodes(&plan, 2)
            .into_iter()
            .map(|r| svetlo::methods::render_passes(spec, &cbox, &RenderSettings { threads: 1, ..s.clone() }, r, &refs, &Progress::new()).unwrap())
            .collect();
        assert_same(&PartialFilm::merge(parts).unwrap(), &local, &format!("photon batches cut at {cuts:?}"));
    }
    // Batches missing, out of order or cut short are refused.
    let a = svetlo::methods::shared_batch(spec, &cbox, &s, 0..3000, &Progress::new()).unwrap();
    let b = svetlo::methods::shared_batch(spec, &cbox, &s, 3000..4000, &Progress::new()).unwrap();
    for bad in [vec![&a[..]], vec![&b[..], &a[..]], vec![&a[..], &b[..b.len() - 1]]] {
        assert!(svetlo::methods::render_passes(spec, &cbox, &s, 0..plan.len() as u32, &bad, &Progress::new()).is_err());
    }
    assert!(svetlo::methods::shared_batch(spec, &cbox, &s, 3000..4001, &Progress::new()).is_err());
}

/// Photons carry their light state in their bytes: batches traced apart with AOVs give the
/// local render's beauty and layers bit for bit (the caustic layer's photons come from the
/// caustic map, the diffuse one's from the global map).
#[test]
fn photon_batches_with_aovs_are_the_local_render_bit_for_bit() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/caustic.xml");
    let sc = svetlo::io::load_scene(&p, &[("res".into(), "16".into())]).expect("scenes/caustic.xml");
    let list = vec![("caustic".to_string(), "C D S+ L".to_string()), ("d2".to_string(), "C D D .* L".to_string())];
    let mut set = svetlo::lpe::AovSet::compile(&list, None).expect("expressions");
    assert!(set.bind(&sc).is_empty());
    let s = RenderSettings { spp: 3, max_depth: 6, seed: 5, threads: 2, filter: svetlo::film::Filter::Box, lpe: Some(Arc::new(set)), ..Default::default() };
    let spec = "photon:photons=3000,caustic-photons=2000,gather=2";
    let local = svetlo::methods::by_name(spec).unwrap().render(&sc, &s, &Progress::new()).unwrap();
    assert_eq!(local.layer_names().len(), 2);
    assert!(local.layer_images().iter().all(|(_, img)| img.data.iter().any(|c| c.r > 0.0)), "every layer has light");
    let plan = pass_plan(s.spp, 16 * 16);
    for cuts in [vec![0, 5000], vec![0, 1700, 3000, 4100, 5000]] {
        let batches: Vec<Vec<u8>> = cuts.windows(2).map(|c| svetlo::methods::shared_batch(spec, &sc, &s, c[0]..c[1], &Progress::new()).unwrap()).collect();
        let refs: Vec<&[u8]> = batches.iter().map(|b| b.as_slice()).collect();
        let parts = chunk_nodes(&plan, 2)
            .into_iter()
            .map(|r| svetlo::methods::render_passes(spec, &sc, &RenderSettings { threads: 1, ..s.clone() }, r, &refs, &Progress::new()).unwrap())
            .collect();
        assert_same(&PartialFilm::merge(parts).unwrap(), &local, &format!("photon batches with AOVs cut at {cuts:?}"));
    }
}

/// Radiosity in pieces: the form-factor rows in `batches` ranges (each through bytes, handed
/// over in reverse order), one solve from them, and the display's passes in `chunks` nodes,
/// each from the solution's bytes.
fn radiosity_in_pieces(spec: &str, sc: &Scene, s: &RenderSettings, batches: u64, chunks: usize) -> (Film, u64) {
    let rows = svetlo::methods::radiosity_rows(spec, sc, s).unwrap_or_else(|e| panic!("{spec}: {e}"));
    let k = batches.min(rows).max(1);
    let cuts: Vec<u64> = if rows == 0 { vec![] } else { (0..=k).map(|i| i * rows / k).collect() };
    let mut blocks: Vec<Vec<u8>> = cuts.windows(2).map(|w| svetlo::methods::radiosity_row_batch(spec, sc, s, w[0]..w[1]).expect("rows")).collect();
    blocks.reverse();
    let refs: Vec<&[u8]> = blocks.iter().map(|b| b.as_slice()).collect();
    let solution = svetlo::methods::radiosity_solve(spec, sc, s, &refs).expect("solve");
    let plan = pass_plan(s.spp, sc.camera.width as u64 * sc.camera.height as u64);
    let parts = chunk_nodes(&plan, chunks)
        .into_iter()
        .map(|r| {
            let part = svetlo::methods::render_passes(spec, sc, s, r, &[&solution], &Progress::new()).expect("passes");
            PartialFilm::from_bytes(&part.to_bytes()).expect("round trip")
        })
        .collect();
    (PartialFilm::merge(parts).expect("merge"), rows)
}

#[test]
fn radiosity_from_rows_computed_apart_and_one_shared_solve_is_the_local_render_bit_for_bit() {
    let cbox = scene("cornell-box.xml", 16, 12);
    let s = RenderSettings { spp: 5, max_depth: -1, seed: 3, threads: 2, ..RenderSettings::from_scene(&cbox) };
    let solve_here = |spec: &str| {
        let o = svetlo::radiosity::RadiosityOptions::parse(spec.split_once(':').map_or("", |(_, o)| o)).unwrap();
        svetlo::radiosity::solve(&cbox, &o, s.max_depth).unwrap()
    };
    for (spec, spread) in [
        ("radiosity:element-size=1", true),
        ("radiosity:element-size=1,form-factors=hemicube,hemicube-resolution=16", true),
        ("radiosity:element-size=1,form-factors=raycast,rays=64,seed=2,shading=flat,reciprocity=true,solver=jacobi", true),
        ("radiosity:element-size=1,form-factors=hemicube,hemicube-resolution=16,hybrid=true,gather=2", true),
        ("radiosity:element-size=1,solver=progressive", false),
        ("radiosity:solver=hierarchical,element-size=1,epsilon=0.2", false),
    ] {
        let local = svetlo::methods::by_name(spec).unwrap().render(&cbox, &s, &Progress::new()).unwrap();
        assert!(local.image().mean().max_component() > 0.0, "{spec}: black image");
        let n = solve_here(spec).b.len() as u64;
        // 7 batches do not divide the rows; one batch is the whole matrix.
        for (batches, chunks) in [(7, 3), (1, 1)] {
            let (film, rows) = radiosity_in_pieces(spec, &cbox, &s, batches, chunks);
            assert_eq!(rows > 0, spread, "{spec}: rows spread");
            if spread {
                assert_eq!(rows, n, "{spec}: one row per element");
                assert_ne!(rows % 7, 0, "{spec}: the test wants 7 batches that do not divide {rows} rows");
            }
            assert_same(&local, &film, &format!("{spec}, {batches} row batches, {chunks} chunks"));
        }
    }
    // The solve from rows computes none itself.
    let spec = "radiosity:element-size=1,form-factors=hemicube,hemicube-resolution=8";
    let o = svetlo::radiosity::RadiosityOptions::parse("element-size=1,form-factors=hemicube,hemicube-resolution=8").unwrap();
    let rows = svetlo::methods::radiosity_rows(spec, &cbox, &s).unwrap();
    let all = svetlo::methods::radiosity_row_batch(spec, &cbox, &s, 0..rows).unwrap();
    let solved = svetlo::radiosity::split::solve_from_rows(&cbox, &o, s.max_depth, &[&all]).unwrap();
    assert_eq!(solved.rows_computed, rows);
}

#[test]
fn radiosity_rows_and_solutions_that_do_not_fit_are_errors() {
    let cbox = scene("cornell-box.xml", 8, 6);
    let s = RenderSettings { spp: 2, ..RenderSettings::from_scene(&cbox) };
    let spec = "radiosity:element-size=1,form-factors=hemicube,hemicube-resolution=8";
    let rows = svetlo::methods::radiosity_rows(spec, &cbox, &s).unwrap();
    assert!(rows > 4);
    let half = rows / 2;
    let a = svetlo::methods::radiosity_row_batch(spec, &cbox, &s, 0..half).unwrap();
    let b = svetlo::methods::radiosity_row_batch(spec, &cbox, &s, half..rows).unwrap();
    let solve = |blocks: &[&[u8]]| svetlo::methods::radiosity_solve(spec, &cbox, &s, blocks);
    assert!(solve(&[&a]).unwrap_err().to_string().contains(&format!("rows 0..{half} of {rows}")));
    assert!(solve(&[&a, &a, &b]).is_err(), "a block twice");
    assert!(svetlo::methods::radiosity_row_batch(spec, &cbox, &s, 0..rows + 1).is_err(), "rows past the mesh");
    assert!(svetlo::methods::radiosity_row_batch(spec, &cbox, &s, 3..3).is_err(), "no rows");
    for cut in [0, 7, 20, b.len() - 1] {
        assert!(solve(&[&a, &b[..cut]]).is_err(), "rows cut at {cut}");
    }
    // Rows of another mesh (another element size) do not fit.
    let other = "radiosity:element-size=0.7,form-factors=hemicube,hemicube-resolution=8";
    let c = svetlo::methods::radiosity_row_batch(other, &cbox, &s, 0..1).unwrap();
    assert!(solve(&[&a, &b, &c]).is_err());
    // Hierarchical radiosity spreads no rows: given some, the solve refuses them.
    let hr = "radiosity:solver=hierarchical,element-size=1,epsilon=0.2";
    assert_eq!(svetlo::methods::radiosity_rows(hr, &cbox, &s).unwrap(), 0);
    assert!(svetlo::methods::radiosity_solve(hr, &cbox, &s, &[&a]).is_err());
    assert!(svetlo::methods::radiosity_row_batch(hr, &cbox, &s, 0..1).is_err());
    // A solution: truncated, or of another mesh, is an error, never a panic.
    let sol = solve(&[&b, &a]).unwrap();
    for cut in [0, 8, 30, sol.len() / 2, sol.len() - 1] {
        assert!(svetlo::methods::render_passes(spec, &cbox, &s, 0..1, &[&sol[..cut]], &Progress::new()).is_err(), "solution cut at {cut}");
    }
    let theirs = svetlo::methods::radiosity_solve(
        other,
        &cbox,
        &s,
        &[&svetlo::methods::radiosity_row_batch(other, &cbox, &s, 0..svetlo::methods::radiosity_rows(other, &cbox, &s).unwrap()).unwrap()],
    )
    .unwrap();
    let mut wrong_mesh = theirs.clone();
    // Same values, this mesh's options: the element count does not match.
    let opts_at = 8 + 2 + 1;
    wrong_mesh[opts_at..opts_at + 4].copy_from_slice(&1.0f32.to_le_bytes());
    assert!(svetlo::methods::render_passes(spec, &cbox, &s, 0..1, &[&wrong_mesh], &Progress::new()).is_err());
    assert!(svetlo::methods::render_passes(spec, &cbox, &s, 0..1, &[&sol, &sol], &Progress::new()).is_err(), "two solutions");
}

/// Parts joined with their siblings as they arrive (as the Dask client does), in any arrival
/// order, merge into the local render's bits; parts that are not two halves of a node do not
/// join.
#[test]
fn parts_joined_as_they_arrive_are_the_local_render_bit_for_bit() {
    let cbox = scene("cornell-box.xml", 12, 10);
    let mut set = svetlo::lpe::AovSet::compile(&[("direct".to_string(), "C <R.> L".to_string())], None).expect("expression");
    assert!(set.bind(&cbox).is_empty());
    let s = RenderSettings { spp: 37, max_depth: 4, seed: 3, threads: 1, lpe: Some(Arc::new(set)), ..RenderSettings::from_scene(&cbox) };
    let plan = pass_plan(s.spp, 120);
    let total = plan.len() as u32;
    let local = svetlo::methods::by_name("bdpt").unwrap().render(&cbox, &s, &Progress::new()).unwrap();
    let nodes = chunk_nodes(&plan, 6);
    let parts: Vec<PartialFilm> =
        nodes.iter().map(|r| svetlo::methods::render_passes("bdpt", &cbox, &s, r.clone(), &[], &Progress::new()).expect("part")).collect();
    // The sibling and side of a node, found from the root as the client finds them.
    let family = |r: &std::ops::Range<u32>| -> (std::ops::Range<u32>, bool) {
        let (mut a, mut b) = (0, total);
        loop {
            let m = svetlo::integrator::passes::split(a, b);
            if *r == (a..m) || *r == (m..b) {
                return if r.start == a { (m..b, true) } else { (a..m, false) };
            }
            (a, b) = if r.end <= m { (a, m) } else { (m, b) };
        }
    };
    let mut rng = svetlo::sampling::rng::Pcg32::new(11, 5);
    for round in 0..6 {
        let mut order: Vec<usize> = (0..parts.len()).collect();
        if round > 0 {
            for i in (1..order.len()).rev() {
                order.swap(i, (rng.next_u32() as usize) % (i + 1));
            }
        }
        let mut held: Vec<PartialFilm> = Vec::new();
        let mut most = 0;
        for &i in &order {
            let mut p = PartialFilm::from_bytes(&parts[i].to_bytes()).expect("round trip");
            while p.passes != (0..total) {
                let (sib, left) = family(&p.passes);
                let Some(k) = held.iter().position(|q| q.passes == sib) else { break };
                let q = held.swap_remove(k);
                p = if left { PartialFilm::join(p, q) } else { PartialFilm::join(q, p) }.expect("siblings join");
            }
            held.push(p);
            most = most.max(held.len());
        }
        assert_eq!(held.len(), 1, "order {order:?}: one part left");
        assert!(most <= 1 + (total as f32).log2().ceil() as usize, "order {order:?}: held {most} parts at once");
        assert_same(&local, &PartialFilm::merge(held).expect("merge"), &format!("arrival order {order:?}"));
    }
    // Not siblings: neighbours across a split, a part with itself, parts of another render.
    let (a, b, c) = (&parts[0], &parts[1], &parts[2]);
    assert!(svetlo::integrator::passes::is_node(&(a.passes.start..b.passes.end), total));
    assert!(PartialFilm::join(b.clone(), c.clone()).is_err(), "{:?} and {:?}", b.passes, c.passes);
    assert!(PartialFilm::join(b.clone(), a.clone()).is_err(), "the wrong way round");
    assert!(PartialFilm::join(a.clone(), a.clone()).is_err(), "a part with itself");
    let other = scene("cornell-box.xml", 12, 11);
    let o = svetlo::methods::render_passes("bdpt", &other, &s, b.passes.clone(), &[], &Progress::new()).expect("part");
    assert!(PartialFilm::join(a.clone(), o).is_err(), "another film size");
}
