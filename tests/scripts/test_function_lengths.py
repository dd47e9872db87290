#!/usr/bin/env python3
"""scripts/function_lengths.py against a source whose function lengths are known: braces in
comments, strings and character literals are not counted; lambdas count toward their function;
class bodies, namespaces, brace initializers and initializer lists are not functions; an access
specifier does not start a function; --max fails on a long one.

    tests/scripts/test_function_lengths.py SOURCE_DIR
"""
import subprocess
import sys
import tempfile
from pathlib import Path

root = Path(sys.argv[1])
script = root / "scripts" / "function_lengths.py"
source = r'''
namespace ts {
namespace {
int three(int x) {   // { a brace in a comment
  return x + '{';
}
}  // namespace

struct S {
  int v = 0;
  int w{2};
  S() : v(1) {}
  S(int a, int b) : v{a}, w{b} {
    if (a > b) {
      v = b;
    }
  }

 public:
  int get() const {
    return v;
  }
  template <class T>
  T twice(T t) const requires true {
    return t + t;
  }
};

const int table[] = {1, 2, 3};

/* } a block comment
   { over lines */
int with_lambda(int y) {
  auto f = [](int z) {
    return z * 2;
  };
  const char* s = "}}}";
  return f(y) + s[0];
}

void long_one() {
''' + "  int a = 0;\n" * 85 + '''}
}  // namespace ts
'''

with tempfile.TemporaryDirectory() as tmp:
    f = Path(tmp) / "x.cpp"
    f.write_text(source)
    p = subprocess.run([sys.executable, str(script), str(f)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    got = [(line.split(": ")[1], int(line.split(": ")[2].split()[0])) for line in p.stdout.splitlines()]
    want = [("three", 3), ("S", 1), ("S", 5), ("get", 3), ("twice", 4), ("with_lambda", 7), ("long_one", 87)]
    assert got == want, (got, want)
    p = subprocess.run([sys.executable, str(script), "--max", "80", tmp], capture_output=True, text=True)
    assert p.returncode == 1 and p.stdout.strip().endswith("long_one: 87 lines"), (p.returncode, p.stdout)
    p = subprocess.run([sys.executable, str(script), "--max", "87", tmp], capture_output=True, text=True)
    assert p.returncode == 0 and p.stdout == "", (p.returncode, p.stdout)
print("function_lengths: ok")
