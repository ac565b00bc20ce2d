//! CS184 camera settings files (what the GUI's `C` key dumps and `-c` reads):
//!
//! ```text
//! hFov vFov ar nClip fClip
//! pos.x pos.y pos.z target.x target.y target.z
//! phi theta r minR maxR
//! c2w(0,0) c2w(0,1) ... c2w(2,2)        (row-major)
//! screenW screenH screenDist
//! [focalDistance lensRadius]             (optional)
//! ```
//!
//! Fields of view are in degrees (`ar` = hFov's tangent over vFov's, as CS184 writes it, is
//! not read), the clip distances in scene units. raypack reads the fields of view, the clip
//! distances, the position and `c2w` (columns: the camera's right, up and backward axes);
//! the target, the spherical coordinates of line 3 and the screen size are CS184's GUI state
//! and are not used. Text from `#` to the end of a line is a comment (a raypack extension:
//! CS184 itself does not skip comments); [`format_camera_file`] writes a commented file.

use crate::io::LoadError;
use crate::math::{Mat3, Vec3};
use crate::scene::Camera;
use std::path::Path;

/// Reads a CS184 camera settings file: a regular file of at most
/// [`crate::fs::input::MAX_CAMERA_FILE_BYTES`] (a FIFO or a device is an error, not a hang).
pub fn load_camera_file(path: &Path) -> Result<Camera, LoadError> {
    let io = |source| LoadError::Io { path: path.to_path_buf(), source };
    let bytes =
        crate::fs::input::read_regular(path, crate::fs::input::MAX_CAMERA_FILE_BYTES, "camera files").map_err(io)?;
    let text = String::from_utf8(bytes)
        .map_err(|e| LoadError::parse(path, format!("byte {}", e.utf8_error().valid_up_to()), "not UTF-8 text"))?;
    parse_camera_file(&text).map_err(|(line, message)| LoadError::Parse {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        message,
    })
}

/// Parses the text of a camera settings file; errors carry the 1-based line.
pub fn parse_camera_file(text: &str) -> Result<Camera, (usize, String)> {
    let mut nums = Vec::with_capacity(32);
    let mut last_line = 1;
    for (i, line) in text.lines().enumerate() {
        let line = line.split_once('#').map_or(line, |(data, _comment)| data);
        for tok in line.split_whitespace() {
            let v: f32 = tok.parse().map_err(|_| (i + 1, format!("expected a number, found {tok:?}")))?;
            if !v.is_finite() {
                return Err((i + 1, format!("{tok} is not a finite number")));
            }
            nums.push(v);
        }
        last_line = i + 1;
    }
    const NEEDED: usize = 5 + 6 + 5 + 9 + 3;
    if nums.len() < NEEDED {
        return Err((last_line, format!("truncated: expected at least {NEEDED} numbers, found {}", nums.len())));
    }
    let (hfov, vfov, near, far) = (nums[0], nums[1], nums[3], nums[4]);
    if !(hfov > 0.0 && hfov < 180.0 && vfov > 0.0 && vfov < 180.0) {
        return Err((1, format!("fields of view must be in (0, 180) degrees, found {hfov} and {vfov}")));
    }
    if !(near >= 0.0 && far > near) {
        return Err((1, format!("clip planes must satisfy 0 <= near < far, found {near} and {far}")));
    }
    let position = Vec3::new(nums[5], nums[6], nums[7]);
    let m = &nums[16..25];
    let c2w = Mat3::from_cols(
        Vec3::new(m[0], m[3], m[6]).normalize_or_zero(),
        Vec3::new(m[1], m[4], m[7]).normalize_or_zero(),
        Vec3::new(m[2], m[5], m[8]).normalize_or_zero(),
    );
    if c2w.determinant().abs() < 0.5 {
        return Err((4, "the camera-to-world matrix is not a rotation".into()));
    }
    Ok(Camera { position, c2w, hfov_deg: hfov, vfov_deg: vfov, near, far })
}

/// `camera` as a commented CS184 camera settings file that [`parse_camera_file`] reads back
/// to the same camera (every number is written with enough digits to round-trip). `target`
/// is the point looked at (written for CS184's GUI; one unit ahead when `None`), `screen` the
/// image size in pixels.
pub fn format_camera_file(camera: &Camera, target: Option<Vec3>, screen: (usize, usize)) -> String {
    let p = camera.position;
    let t = target.unwrap_or(p + camera.view_dir());
    let r = (p - t).length();
    let d = (p - t).normalize_or(Vec3::Z);
    let (phi, theta) = (d.y.clamp(-1.0, 1.0).acos(), d.x.atan2(d.z));
    // `+ 0.0` writes -0 as 0.
    let (p, t, m) = (p + Vec3::ZERO, t + Vec3::ZERO, camera.c2w + Mat3::ZERO);
    let ar = (camera.hfov_deg.to_radians() * 0.5).tan() / (camera.vfov_deg.to_radians() * 0.5).tan();
    format!(
        "# raypack / CS184 camera settings file (read with `raypack render -c FILE`).\n\
         # Text after '#' is a comment. Angles in degrees, distances in scene units.\n\
         # hFov vFov aspect near far\n\
         {} {} {} {} {}\n\
         # position (x y z), then target (x y z)\n\
         {} {} {} {} {} {}\n\
         # phi theta r minR maxR: CS184's orbit around the target (radians; raypack ignores this line)\n\
         {} {} {} {} {}\n\
         # camera-to-world rotation, row-major; its columns are the camera's right, up and backward axes\n\
         {} {} {}\n{} {} {}\n{} {} {}\n\
         # screenW screenH screenDist (CS184's window; raypack ignores this line)\n\
         {} {} {}\n",
        camera.hfov_deg,
        camera.vfov_deg,
        ar,
        camera.near,
        camera.far,
        p.x,
        p.y,
        p.z,
        t.x,
        t.y,
        t.z,
        phi,
        theta,
        r,
        r * 0.1,
        r * 10.0,
        m.x_axis.x,
        m.y_axis.x,
        m.z_axis.x,
        m.x_axis.y,
        m.y_axis.y,
        m.z_axis.y,
        m.x_axis.z,
        m.y_axis.z,
        m.z_axis.z,
        screen.0,
        screen.1,
        screen.1 as f32 * 0.5 / (camera.vfov_deg.to_radians() * 0.5).tan(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "49.1343 38.1 1.333 0.1 100\n0 1 5 0 1 0 \n1.57 0 5 1 50\n1 0 0 0 1 0 0 0 1 \n480 360 1\n";

    #[test]
    fn reads_cs184_dump() {
        let c = parse_camera_file(FILE).unwrap();
        assert_eq!(c.position, Vec3::new(0.0, 1.0, 5.0));
        assert_eq!((c.near, c.far), (0.1, 100.0));
        assert!((c.view_dir() - -Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn formatted_file_reads_back_to_the_same_camera() {
        let cam = Camera::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::new(-0.5, 0.25, 0.0), Vec3::Y, 37.5, 1.5, 0.01, 80.0);
        let text = format_camera_file(&cam, Some(Vec3::new(-0.5, 0.25, 0.0)), (480, 320));
        assert!(text.lines().filter(|l| l.starts_with('#')).count() >= 5, "commented:\n{text}");
        let back = parse_camera_file(&text).unwrap();
        assert_eq!(
            (back.position, back.hfov_deg, back.vfov_deg, back.near, back.far),
            (cam.position, cam.hfov_deg, cam.vfov_deg, cam.near, cam.far)
        );
        // The parser re-normalises the axes: equal to within rounding.
        assert!(
            (back.c2w - cam.c2w).abs().to_cols_array().iter().all(|&e| e < 1e-6),
            "{:?} vs {:?}",
            back.c2w,
            cam.c2w
        );
        // Comments anywhere on a line.
        assert_eq!(parse_camera_file(&FILE.replace("\n", " # note\n")).unwrap(), parse_camera_file(FILE).unwrap());
    }

    #[test]
    fn reports_line_of_bad_token_and_truncation() {
        assert_eq!(parse_camera_file("49 38 1 0.1 100\n0 x").unwrap_err().0, 2);
        assert!(parse_camera_file("49 38 1 0.1 100\n").unwrap_err().1.contains("truncated"));
    }
}
