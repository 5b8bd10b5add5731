//! `SceneSettings::ray_epsilon` (`--ray-epsilon`): hits closer than it to a ray's origin are
//! skipped on every ray, closest-hit and shadow, static and moving shapes alike, and a hit
//! beyond it is reported at its distance from the ray's own origin.

use glam::Vec3;
use svetlo::geometry::Ray;
use svetlo::scene::Scene;

/// Two unit squares facing -z, at z = 0 and z = 0.001; with `moving`, a third one at z = 0.002
/// that moves (at times 0 and 1 it is at the same place, so only the moving code path differs).
fn scene(moving: bool) -> Scene {
    let dir = std::env::temp_dir().join(format!("svetlo-ray-epsilon-{}-{moving}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let square = |z: f32| format!(r#"<shape type="rectangle"><transform name="to_world"><translate z="{z}"/></transform></shape>"#);
    let mover = if moving {
        r#"<shape type="rectangle"><animation name="to_world">
             <transform time="0"><translate z="0.002"/></transform>
             <transform time="1"><translate z="0.002"/></transform></animation></shape>"#
    } else {
        ""
    };
    let xml = format!(
        r#"<scene version="3.0.0">
             <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, -3" target="0, 0, 0" up="0, 1, 0"/></transform>
               <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
             {}{}{mover}
             <emitter type="constant"/>
           </scene>"#,
        square(0.0),
        square(0.001)
    );
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).expect("write");
    let s = svetlo::io::load_scene(&path, &[]).expect("load");
    let _ = std::fs::remove_dir_all(&dir);
    s
}

#[test]
fn hits_nearer_than_the_epsilon_are_skipped_and_distances_are_from_the_origin() {
    for moving in [false, true] {
        let mut s = scene(moving);
        let ray = Ray::new(Vec3::new(0.1, 0.2, -0.0003), Vec3::Z);
        let hit = s.intersect(&ray).expect("hit");
        assert!((hit.t - 3e-4).abs() < 1e-6 && hit.p.z.abs() < 1e-6, "no epsilon: the first square, t {}", hit.t);
        s.settings.ray_epsilon = 5e-4;
        let hit = s.intersect(&ray).expect("hit");
        assert!((hit.t - 1.3e-3).abs() < 1e-6, "moving {moving}: t {} from the ray's origin, p {:?}", hit.t, hit.p);
        assert!((hit.p.z - 1e-3).abs() < 1e-6 && (hit.p.x - 0.1).abs() < 1e-6, "moving {moving}: p {:?}", hit.p);
        assert!((s.intersect_prim(&ray).expect("prim").t - 1.3e-3).abs() < 1e-6);
        // Past both static squares only the moving one is left.
        let far = Ray::new(Vec3::new(0.1, 0.2, 0.0007), Vec3::Z);
        match s.intersect(&far) {
            Some(h) => assert!(moving && (h.t - 1.3e-3).abs() < 1e-6 && (h.p.z - 2e-3).abs() < 1e-6, "moving {moving}: {:?}", h.p),
            None => assert!(!moving),
        }
        // Shadow rays: a segment whose only blocker is within the epsilon is free.
        let (p0, p1) = (Vec3::new(0.1, 0.2, -0.0003), Vec3::new(0.1, 0.2, 0.0005));
        assert!(!s.occluded_at(p0, Vec3::ZERO, p1, 0.5), "moving {moving}");
        assert!(s.occluded_at(p0, Vec3::ZERO, Vec3::new(0.1, 0.2, 0.5), 0.5), "moving {moving}: the second square blocks");
        s.settings.ray_epsilon = 0.0;
        assert!(s.occluded_at(p0, Vec3::ZERO, p1, 0.5), "moving {moving}: without the epsilon the first square blocks");
        // A ray shorter than the epsilon meets nothing.
        s.settings.ray_epsilon = 1.0;
        assert!(s.intersect(&Ray::with_max(ray.o, ray.d, 0.5)).is_none());
    }
}
