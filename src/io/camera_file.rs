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

use crate::io::LoadError;
use crate::math::{Mat3, Vec3};
use crate::scene::Camera;
use std::path::Path;

/// Reads a CS184 camera settings file: a regular file of at most
/// [`crate::io::input::MAX_CAMERA_FILE_BYTES`] (a FIFO or a device is an error, not a hang).
pub fn load_camera_file(path: &Path) -> Result<Camera, LoadError> {
    let io = |source| LoadError::Io { path: path.to_path_buf(), source };
    let bytes =
        crate::io::input::read_regular(path, crate::io::input::MAX_CAMERA_FILE_BYTES, "camera files").map_err(io)?;
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
    fn reports_line_of_bad_token_and_truncation() {
        assert_eq!(parse_camera_file("49 38 1 0.1 100\n0 x").unwrap_err().0, 2);
        assert!(parse_camera_file("49 38 1 0.1 100\n").unwrap_err().1.contains("truncated"));
    }
}
