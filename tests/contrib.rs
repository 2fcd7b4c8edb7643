//! The launchers in `contrib/` and `docker-compose.yml`, as far as CI can check them without
//! root, daemons or a cluster: the shell scripts parse (`bash -n`), Slurm sees every `#SBATCH`
//! line, the Kubernetes manifests and the compose file parse and hold together (names, labels,
//! ports, Secrets, volumes, the files `vtfarm cluster init` writes), and the two Dockerfiles share
//! one runtime stage. `contrib/slurm/test-local.sh` and `contrib/docker/test-local.sh` run them
//! for real.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::Deserialize as _;
use serde_norway::Value;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn read(path: &str) -> String {
    std::fs::read_to_string(repo(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Every YAML document in the file, with `<<` merge keys applied.
fn yaml_documents(path: &str) -> Vec<Value> {
    let text = read(path);
    serde_norway::Deserializer::from_str(&text)
        .map(|document| {
            let mut value =
                Value::deserialize(document).unwrap_or_else(|e| panic!("{path}: not YAML: {e}"));
            value
                .apply_merge()
                .unwrap_or_else(|e| panic!("{path}: bad merge key: {e}"));
            value
        })
        .collect()
}

/// The value at a dotted path (`spec.template.metadata.labels`), or a failure naming it.
fn at<'a>(value: &'a Value, path: &str, context: &str) -> &'a Value {
    path.split('.').fold(value, |value, key| {
        value
            .get(key)
            .unwrap_or_else(|| panic!("{context}: no `{path}` (missing `{key}`)"))
    })
}

fn text_at<'a>(value: &'a Value, path: &str, context: &str) -> &'a str {
    at(value, path, context)
        .as_str()
        .unwrap_or_else(|| panic!("{context}: `{path}` is not a string"))
}

fn list_at<'a>(value: &'a Value, path: &str, context: &str) -> &'a [Value] {
    at(value, path, context)
        .as_sequence()
        .unwrap_or_else(|| panic!("{context}: `{path}` is not a list"))
}

fn strings(values: &[Value]) -> Vec<&str> {
    values.iter().filter_map(Value::as_str).collect()
}

/// The value following `flag` in an argument list.
fn flag_value<'a>(args: &[&'a str], flag: &str, context: &str) -> &'a str {
    args.iter()
        .position(|a| *a == flag)
        .and_then(|i| args.get(i + 1))
        .unwrap_or_else(|| panic!("{context}: no `{flag} VALUE` in {args:?}"))
}

fn port_of(address: &str, context: &str) -> u16 {
    address
        .rsplit_once(':')
        .and_then(|(_, port)| port.parse().ok())
        .unwrap_or_else(|| panic!("{context}: `{address}` has no port"))
}

#[test]
fn shell_scripts_parse_and_slurm_sees_every_sbatch_line() {
    for script in [
        "contrib/slurm/vtfarm.sbatch",
        "contrib/slurm/test-local.sh",
        "contrib/docker/test-local.sh",
        "contrib/test-lib.sh",
    ] {
        let out = Command::new("bash")
            .arg("-n")
            .arg(repo(script))
            .output()
            .expect("bash runs");
        assert!(
            out.status.success(),
            "{script}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // sbatch stops reading directives at the first line that is neither blank nor a comment.
    let sbatch = read("contrib/slurm/vtfarm.sbatch");
    let first_command = sbatch
        .lines()
        .position(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .expect("the script has commands");
    let directives: Vec<usize> = sbatch
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("#SBATCH"))
        .map(|(i, _)| i)
        .collect();
    assert!(!directives.is_empty(), "vtfarm.sbatch has no #SBATCH line");
    for line in directives {
        assert!(
            line < first_command,
            "contrib/slurm/vtfarm.sbatch:{}: #SBATCH after the first command is ignored",
            line + 1
        );
    }
}

/// One Kubernetes object with where it came from.
struct Object {
    file: String,
    value: Value,
}

impl Object {
    fn context(&self) -> String {
        let kind = self
            .value
            .get("kind")
            .and_then(Value::as_str)
            .unwrap_or("?");
        format!("{}: {kind}", self.file)
    }
    fn kind(&self) -> &str {
        text_at(&self.value, "kind", &self.file)
    }
    fn name(&self) -> &str {
        text_at(&self.value, "metadata.name", &self.context())
    }
    fn at(&self, path: &str) -> &Value {
        at(&self.value, path, &self.context())
    }
    /// The pod template's only container whose name is given.
    fn container(&self, list: &str, name: &str) -> &Value {
        list_at(
            &self.value,
            &format!("spec.template.spec.{list}"),
            &self.context(),
        )
        .iter()
        .find(|c| c.get("name").and_then(Value::as_str) == Some(name))
        .unwrap_or_else(|| panic!("{}: no {list} entry `{name}`", self.context()))
    }
    /// The pod's volumes, by name, plus the StatefulSet's claim templates.
    fn volume_names(&self) -> BTreeSet<&str> {
        let mut names: BTreeSet<&str> =
            list_at(&self.value, "spec.template.spec.volumes", &self.context())
                .iter()
                .map(|v| text_at(v, "name", &self.context()))
                .collect();
        if let Some(claims) = self
            .value
            .get("spec")
            .and_then(|s| s.get("volumeClaimTemplates"))
        {
            let claims = claims
                .as_sequence()
                .expect("volumeClaimTemplates is a list");
            names.extend(
                claims
                    .iter()
                    .map(|c| text_at(c, "metadata.name", &self.context())),
            );
        }
        names
    }
    /// The Secret a pod volume mounts, if it is one.
    fn secret_of_volume(&self, volume: &str) -> Option<&str> {
        list_at(&self.value, "spec.template.spec.volumes", &self.context())
            .iter()
            .find(|v| v.get("name").and_then(Value::as_str) == Some(volume))?
            .get("secret")
            .map(|s| text_at(s, "secretName", &self.context()))
    }
}

fn mounts(container: &Value, context: &str) -> Vec<(String, String)> {
    list_at(container, "volumeMounts", context)
        .iter()
        .map(|m| {
            (
                text_at(m, "name", context).to_owned(),
                text_at(m, "mountPath", context).to_owned(),
            )
        })
        .collect()
}

/// The volume mounted at the directory holding `file`.
fn volume_holding(container: &Value, file: &str, context: &str) -> String {
    let dir = Path::new(file).parent().expect("an absolute path");
    mounts(container, context)
        .into_iter()
        .find(|(_, path)| Path::new(path) == dir)
        .map(|(name, _)| name)
        .unwrap_or_else(|| panic!("{context}: nothing is mounted at {}", dir.display()))
}

#[test]
fn kubernetes_manifests_hold_together() {
    let kustomization = yaml_documents("contrib/k8s/kustomization.yaml").remove(0);
    let context = "contrib/k8s/kustomization.yaml";
    assert_eq!(text_at(&kustomization, "kind", context), "Kustomization");
    let objects: Vec<Object> = strings(list_at(&kustomization, "resources", context))
        .into_iter()
        .flat_map(|file| {
            let file = format!("contrib/k8s/{file}");
            yaml_documents(&file).into_iter().map(move |value| Object {
                file: file.clone(),
                value,
            })
        })
        .collect();
    for object in &objects {
        for field in ["apiVersion", "kind", "metadata.name"] {
            text_at(&object.value, field, &object.file);
        }
    }
    let kinds: BTreeSet<&str> = objects.iter().map(Object::kind).collect();
    assert_eq!(
        kinds,
        BTreeSet::from(["Deployment", "Service", "StatefulSet"])
    );
    let find = |kind: &str| {
        objects
            .iter()
            .find(|o| o.kind() == kind)
            .expect("kind present")
    };
    let (service, master, workers) = (find("Service"), find("StatefulSet"), find("Deployment"));

    // The Secrets come from exactly the files `vtfarm cluster init` writes.
    let generated: Vec<(&str, Vec<&str>)> = list_at(&kustomization, "secretGenerator", context)
        .iter()
        .map(|s| {
            (
                text_at(s, "name", context),
                strings(list_at(s, "files", context)),
            )
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let init = Command::new(env!("CARGO_BIN_EXE_vtfarm"))
        .args(["cluster", "init", "-o"])
        .arg(dir.path().join("cluster"))
        .args(["--master", &format!("{}:7878", service.name())])
        .output()
        .expect("vtfarm runs");
    assert!(
        init.status.success(),
        "{}",
        String::from_utf8_lossy(&init.stderr)
    );
    let mut written: Vec<String> = std::fs::read_dir(dir.path().join("cluster"))
        .unwrap()
        .map(|e| format!("cluster/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    written.sort();
    let mut listed: Vec<&str> = generated
        .iter()
        .flat_map(|(_, files)| files.clone())
        .collect();
    listed.sort();
    assert_eq!(listed, written, "{context}: secretGenerator files");
    let secret_files = |secret: &str| -> Vec<&str> {
        let (_, files) = generated
            .iter()
            .find(|(name, _)| *name == secret)
            .unwrap_or_else(|| panic!("no Secret `{secret}` in {context}"));
        files
            .iter()
            .map(|f| f.trim_start_matches("cluster/"))
            .collect()
    };

    // Selectors pick their own pod templates, and the Service picks the master.
    for object in [master, workers] {
        let selector = object.at("spec.selector.matchLabels").as_mapping().unwrap();
        let labels = object
            .at("spec.template.metadata.labels")
            .as_mapping()
            .unwrap();
        for (key, value) in selector {
            assert_eq!(
                labels.get(key),
                Some(value),
                "{}: selector {key:?}",
                object.context()
            );
        }
        let picked = service
            .at("spec.selector")
            .as_mapping()
            .unwrap()
            .iter()
            .all(|(key, value)| labels.get(key) == Some(value));
        assert_eq!(
            picked,
            object.kind() == "StatefulSet",
            "the Service's selector on {}",
            object.context()
        );
    }
    assert_eq!(
        text_at(&master.value, "spec.serviceName", &master.context()),
        service.name()
    );

    // The master listens where the Service sends UDP, and its cluster file's directory (its
    // state) is on the claim template's volume, filled from both Secrets by the init container.
    let master_container = master.container("containers", "master");
    let master_args = strings(list_at(master_container, "args", &master.context()));
    let service_port = &list_at(&service.value, "spec.ports", &service.context())[0];
    assert_eq!(text_at(service_port, "protocol", &service.context()), "UDP");
    let target = text_at(service_port, "targetPort", &service.context());
    let container_port = list_at(master_container, "ports", &master.context())
        .iter()
        .find(|p| p.get("name").and_then(Value::as_str) == Some(target))
        .unwrap_or_else(|| panic!("{}: no container port `{target}`", master.context()));
    assert_eq!(
        text_at(container_port, "protocol", &master.context()),
        "UDP"
    );
    let listen = flag_value(&master_args, "--listen", &master.context());
    assert_eq!(
        Some(u64::from(port_of(listen, &master.context()))),
        container_port.get("containerPort").and_then(Value::as_u64)
    );
    let cluster_file = flag_value(&master_args, "--cluster", &master.context());
    let state = volume_holding(master_container, cluster_file, &master.context());
    let claims = list_at(
        &master.value,
        "spec.volumeClaimTemplates",
        &master.context(),
    );
    assert!(
        claims
            .iter()
            .any(|c| text_at(c, "metadata.name", &master.context()) == state),
        "{}: the state directory is not on a claim template",
        master.context()
    );
    let identity = master.container("initContainers", "identity");
    let copy = strings(list_at(identity, "command", &master.context())).join(" ");
    for (volume, path) in mounts(identity, &master.context()) {
        let Some(secret) = master.secret_of_volume(&volume) else {
            assert_eq!(
                volume,
                state,
                "{}: init container mounts {volume}",
                master.context()
            );
            assert_eq!(Path::new(&path), Path::new(cluster_file).parent().unwrap());
            continue;
        };
        for file in secret_files(secret) {
            assert!(
                copy.contains(&format!("{path}/{file}")),
                "{}: {file} is not copied",
                master.context()
            );
        }
    }

    // Workers read the cluster file from the Secret that holds it.
    let worker = workers.container("containers", "worker");
    let worker_args = strings(list_at(worker, "args", &workers.context()));
    let cluster_file = flag_value(&worker_args, "--cluster", &workers.context());
    let volume = volume_holding(worker, cluster_file, &workers.context());
    let secret = workers
        .secret_of_volume(&volume)
        .unwrap_or_else(|| panic!("{}: {cluster_file} is not from a Secret", workers.context()));
    let file_name = Path::new(cluster_file)
        .file_name()
        .unwrap()
        .to_str()
        .unwrap();
    assert_eq!(
        secret_files(secret),
        [file_name],
        "workers get only the cluster file"
    );

    // Every mount names a volume of its pod.
    for object in [master, workers] {
        let volumes = object.volume_names();
        for list in ["containers", "initContainers"] {
            let Some(containers) = object
                .value
                .get("spec")
                .and_then(|s| s.get("template"))
                .and_then(|t| t.get("spec"))
                .and_then(|s| s.get(list))
            else {
                continue;
            };
            for container in containers.as_sequence().unwrap() {
                for (name, _) in mounts(container, &object.context()) {
                    assert!(
                        volumes.contains(name.as_str()),
                        "{}: no volume `{name}`",
                        object.context()
                    );
                }
            }
        }
    }
}

#[test]
fn compose_file_holds_together() {
    let path = "docker-compose.yml";
    let compose = yaml_documents(path).remove(0);
    let services = at(&compose, "services", path).as_mapping().unwrap();
    let names: BTreeSet<&str> = services.keys().filter_map(Value::as_str).collect();
    assert_eq!(
        names,
        BTreeSet::from(["init", "master", "submit", "worker"])
    );
    let service = |name: &str| at(&compose, &format!("services.{name}"), path);
    let command = |name: &str| {
        strings(list_at(
            service(name),
            "command",
            &format!("{path}: {name}"),
        ))
    };
    let declared: BTreeSet<&str> = at(&compose, "volumes", path)
        .as_mapping()
        .unwrap()
        .keys()
        .filter_map(Value::as_str)
        .collect();
    for name in &names {
        let context = format!("{path}: {name}");
        let service = service(name);
        assert!(
            service.get("image").is_some() && service.get("build").is_some(),
            "{context}: image and build"
        );
        assert_eq!(
            command(name)[0].split_whitespace().count(),
            1,
            "{context}: command is a list"
        );
        for volume in strings(list_at(service, "volumes", &context)) {
            let source = volume.split(':').next().unwrap();
            assert!(
                source.starts_with("./") || declared.contains(source),
                "{context}: volume `{source}` is not declared"
            );
            if *name != "init" && *name != "master" && source == "state" {
                assert!(
                    volume.ends_with(":ro"),
                    "{context}: the master's key is mounted writable"
                );
            }
        }
    }
    // The master listens on the port the cluster file names and the one published, and only on
    // this host's loopback.
    let listen = port_of(flag_value(&command("master"), "--listen", path), path);
    let advertised = port_of(flag_value(&command("init"), "--master", path), path);
    assert_eq!(listen, advertised);
    let published = strings(list_at(service("master"), "ports", path));
    assert_eq!(published.len(), 1);
    assert!(
        published[0].starts_with("127.0.0.1:"),
        "{path}: port published beyond loopback"
    );
    assert!(
        published[0].ends_with(&format!(":{listen}/udp")),
        "{path}: {}",
        published[0]
    );
}

#[test]
fn dockerfiles_share_the_runtime_stage() {
    // The last stage of each, without comments and the line that brings the binary in.
    let runtime = |path: &str| -> Vec<String> {
        let text = read(path);
        let stage = &text[text
            .rfind("\nFROM ")
            .unwrap_or_else(|| panic!("{path}: no FROM"))..];
        stage
            .lines()
            .map(str::trim)
            .filter(|l| {
                !l.is_empty()
                    && !l.starts_with('#')
                    && !l.starts_with("FROM ")
                    && !l.starts_with("COPY ")
            })
            .map(str::to_owned)
            .collect()
    };
    let built = runtime("Dockerfile");
    assert!(
        built.iter().any(|l| l.starts_with("ENTRYPOINT")),
        "Dockerfile: no ENTRYPOINT"
    );
    assert_eq!(built, runtime("contrib/docker/Dockerfile.prebuilt"));
}
