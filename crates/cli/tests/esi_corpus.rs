//! Files of the ESI corpus (`../shared/esi-corpus/`) that the reader refused: two declared
//! ISO-8859-1 ("not UTF-8 text"), one with passive end terminals ("<Type> lacks
//! ProductCode"), and IgH's `ethercat xml` dump (root <EtherCATInfoList>).
use std::process::Command;

fn esi(file: &str, args: &[&str]) -> (bool, String, String) {
    let path = ferrocat_testdata::shared(&format!("esi-corpus/{file}"));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("esi").arg(&path).args(args).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn needs_shared_the_files_once_refused_are_read() {
    for (file, device) in [("Beckhoff EJ6xxx.xml", "EJ6002"), ("Beckhoff EKx9xx.xml", "EK1960-0000")] {
        let (ok, out, err) = esi(file, &[]);
        assert!(ok && out.contains(device) && out.contains("Beckhoff"), "{file}: {err}");
    }
    let (ok, out, err) = esi("Beckhoff EL9xxx.xml", &["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let passive: Vec<&str> = v["passive"].as_array().unwrap().iter().filter_map(|p| p["type"].as_str()).collect();
    assert!(passive.contains(&"EL9010") && passive.contains(&"EL9011"), "{v}");
    assert!(v["devices"].as_array().unwrap().iter().any(|d| d["type"] == "EL9110"), "the terminals with an ESC: {v}");
    let (ok, _, err) = esi("Beckhoff EL9xxx.xml", &["--device", "EL9010"]);
    assert!(!ok && err.contains("EL9010 (line 18) is a passive device"), "{err}");
    let (ok, out, err) = esi("topology.xml", &["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((v["vendor_id"].as_u64(), v["devices"].as_array().map(Vec::len)), (Some(0x22D2), Some(2)), "{v}");
}
