//! Where two JSON values differ, as paths: what a `resume` that cannot reuse saved work
//! says changed.

use serde_json::Value;

/// Each place `a` and `b` differ, as `path: a -> b` (a missing value shown as `none`).
pub fn differences(a: &Value, b: &Value) -> Vec<String> {
    let mut out = Vec::new();
    walk(a, b, String::new(), &mut out);
    out
}

fn walk(a: &Value, b: &Value, path: String, out: &mut Vec<String>) {
    let at = |key: &str| {
        if path.is_empty() {
            key.to_string()
        } else {
            format!("{path}.{key}")
        }
    };
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                walk(
                    x.get(k).unwrap_or(&Value::Null),
                    y.get(k).unwrap_or(&Value::Null),
                    at(k),
                    out,
                );
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                walk(u, v, at(&i.to_string()), out);
            }
        }
        _ if a != b => {
            let show = |v: &Value| {
                if v.is_null() {
                    "none".to_string()
                } else {
                    v.to_string()
                }
            };
            out.push(format!(
                "{}: {} -> {}",
                if path.is_empty() { "value" } else { &path },
                show(a),
                show(b)
            ));
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::differences;

    #[test]
    fn names_each_changed_leaf() {
        let a = serde_json::json!({"a": 1, "b": [1, 2], "c": {"d": true}});
        let b = serde_json::json!({"a": 1, "b": [1, 3], "c": {"d": true, "e": 0}});
        assert_eq!(differences(&a, &b), vec!["b.1: 2 -> 3", "c.e: none -> 0"]);
        assert!(differences(&a, &a).is_empty());
    }
}
