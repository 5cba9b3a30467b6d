//! `ferrocat sii write` loses nothing: an image of another device or larger than the slave's
//! EEPROM is refused before anything is written, the EEPROM as it was is saved first, and what
//! was written is read back (on the embedded virtual segment).
use std::path::{Path, PathBuf};
use std::process::Command;

fn ferrocat(dir: &Path, args: &[&str]) -> (bool, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).current_dir(dir).output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
}

fn workdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ferrocat-sii-write-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

const SEGMENT: [&str; 4] = ["--device", "EK1100", "--device", "SERVO"];

#[test]
fn another_device_s_image_is_refused_unless_asked_and_the_old_contents_are_kept() {
    let d = workdir("identity");
    // The EK1100's image, for the servo at position 1.
    let (ok, err) = ferrocat(&d, &[&["sii", "read", "0", "--out", "ek1100.bin"][..], &SEGMENT].concat());
    assert!(ok, "{err}");
    let (ok, err) = ferrocat(&d, &[&["sii", "read", "1", "--out", "servo.bin"][..], &SEGMENT].concat());
    assert!(ok, "{err}");
    let (ok, err) = ferrocat(&d, &[&["sii", "write", "1", "ek1100.bin"][..], &SEGMENT].concat());
    assert!(!ok, "written");
    assert!(
        err.contains("ek1100.bin is vendor 0x2 product 0x44c2c52 (EK1100); slave 1 is vendor 0x0 product 0x402 (SERVO): nothing written"),
        "{err}"
    );
    assert!(!d.join("sii-backup-slave1.bin").exists(), "a backup before a refusal");
    // Asked: the servo's contents saved first, then the image written and read back.
    let (ok, err) =
        ferrocat(&d, &[&["sii", "write", "1", "ek1100.bin", "--overwrite-identity"][..], &SEGMENT].concat());
    assert!(ok && err.contains("read them back"), "{err}");
    assert!(err.contains("is in sii-backup-slave1.bin"), "{err}");
    assert_eq!(std::fs::read(d.join("sii-backup-slave1.bin")).unwrap(), std::fs::read(d.join("servo.bin")).unwrap());
    // A second write gets a backup of its own; a named one is never overwritten.
    let (ok, err) = ferrocat(&d, &[&["sii", "write", "1", "servo.bin"][..], &SEGMENT].concat());
    assert!(ok && err.contains("sii-backup-slave1.1.bin"), "{err}");
    let (ok, err) =
        ferrocat(&d, &[&["sii", "write", "1", "servo.bin", "--backup", "servo.bin"][..], &SEGMENT].concat());
    assert!(!ok && err.contains("--backup servo.bin: exists"), "{err}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn an_image_larger_than_the_eeprom_is_refused_before_anything_is_written() {
    let d = workdir("size");
    let (ok, err) = ferrocat(&d, &[&["sii", "read", "1", "--out", "servo.bin"][..], &SEGMENT].concat());
    assert!(ok, "{err}");
    // The servo's own image with data past its EEPROM's end (its word 0x3E).
    let mut img = std::fs::read(d.join("servo.bin")).unwrap();
    let size = (u16::from_le_bytes([img[0x7C], img[0x7D]]) as usize + 1) * 128;
    img.resize(size + 64, 0xFF);
    img[size + 10] = 0x42;
    std::fs::write(d.join("big.bin"), &img).unwrap();
    let (ok, err) = ferrocat(&d, &[&["sii", "write", "1", "big.bin"][..], &SEGMENT].concat());
    assert!(!ok, "written");
    let want = format!(
        "big.bin holds {} bytes of data; slave 1's EEPROM holds {size} (its SII word 0x3E): nothing written",
        size + 11
    );
    assert!(err.contains(&want), "{err}");
    assert!(!d.join("sii-backup-slave1.bin").exists());
    std::fs::remove_dir_all(&d).ok();
}
