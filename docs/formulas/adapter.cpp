// An example adapter for `whitted formulas` in C++17, without dependencies.
//
//   g++ -std=c++17 -O2 -o adapter docs/formulas/adapter.cpp
//   whitted formulas --program ./adapter
//
// It reads one JSON request a line on stdin, {"id": N, "formula": NAME, "inputs": {...}},
// and writes one answer a line on stdout, {"id": N, "outputs": {...}}, or
// {"id": N, "error": "..."} for a formula it does not implement (docs/formulas.md).
// Replace a formula's body by a call into your renderer to test your own code.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

// ---- a minimal JSON value: numbers, strings, booleans, null, arrays, objects
struct Json {
    enum Kind { Null, Bool, Number, String, Array, Object } kind = Null;
    double num = 0;
    bool b = false;
    std::string str;
    std::vector<Json> arr;
    std::map<std::string, Json> obj;
    const Json &operator[](const std::string &k) const {
        auto it = obj.find(k);
        if (it == obj.end()) throw std::runtime_error("missing input " + k);
        return it->second;
    }
};

struct Parser {
    const std::string &s;
    size_t i = 0;
    void ws() { while (i < s.size() && isspace((unsigned char) s[i])) ++i; }
    bool eat(char c) { ws(); if (i < s.size() && s[i] == c) { ++i; return true; } return false; }
    Json value() {
        ws();
        Json v;
        if (eat('{')) {
            v.kind = Json::Object;
            if (eat('}')) return v;
            do { Json k = value(); if (!eat(':')) throw std::runtime_error("':'");
                 v.obj[k.str] = value(); } while (eat(','));
            if (!eat('}')) throw std::runtime_error("'}'");
        } else if (eat('[')) {
            v.kind = Json::Array;
            if (eat(']')) return v;
            do v.arr.push_back(value()); while (eat(','));
            if (!eat(']')) throw std::runtime_error("']'");
        } else if (eat('"')) {
            v.kind = Json::String;
            while (i < s.size() && s[i] != '"') {
                if (s[i] == '\\') ++i;   // the names here need no more than skipping escapes
                v.str += s[i++];
            }
            ++i;
        } else if (s.compare(i, 4, "true") == 0) { v.kind = Json::Bool; v.b = true; i += 4; }
        else if (s.compare(i, 5, "false") == 0) { v.kind = Json::Bool; i += 5; }
        else if (s.compare(i, 4, "null") == 0) { i += 4; }
        else { v.kind = Json::Number; size_t n; v.num = std::stod(s.substr(i), &n); i += n; }
        return v;
    }
};

// ---- vectors
struct V { double x, y, z; };
V operator+(V a, V b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V operator-(V a, V b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V operator*(V a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double dot(V a, V b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V cross(V a, V b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
V normalize(V a) { return a * (1 / std::sqrt(dot(a, a))); }
V vec(const Json &j) { return {j.arr.at(0).num, j.arr.at(1).num, j.arr.at(2).num}; }

// ---- writing the outputs
struct Out {
    std::ostringstream o;
    bool first = true;
    Out() { o.precision(17); o << "{"; }
    void key(const char *k) { o << (first ? "" : ", ") << '"' << k << "\": "; first = false; }
    Out &num(const char *k, double v) { key(k); o << v; return *this; }
    Out &flag(const char *k, bool v) { key(k); o << (v ? "true" : "false"); return *this; }
    Out &vec(const char *k, V v) { key(k); o << "[" << v.x << ", " << v.y << ", " << v.z << "]"; return *this; }
    std::string str() { return o.str() + "}"; }
};

// ---- the formulas (conventions: docs/formulas.md)
const double PI = 3.14159265358979323846;

// Snell's law: |cos_i|, n_t / n_i and cos_t (negative under total internal reflection)
void snell(double cos_i, double eta, double &c, double &rel, double &cos_t) {
    rel = cos_i >= 0 ? eta : 1 / eta;
    c = std::fabs(cos_i);
    double sin2_t = (1 - c * c) / (rel * rel);
    cos_t = sin2_t > 1 ? -1 : std::sqrt(1 - sin2_t);
}

std::string sphere_intersect(const Json &in) {
    V o = vec(in["origin"]), d = vec(in["direction"]), f = o - vec(in["center"]);
    double r = in["radius"].num, b = dot(f, d), disc = b * b - (dot(f, f) - r * r);
    if (disc < 0) return Out().flag("hit", false).str();
    double t0 = -b - std::sqrt(disc), t1 = -b + std::sqrt(disc);
    double t = t0 > 0 ? t0 : t1;   // from inside: the far root
    if (t <= 0) return Out().flag("hit", false).str();
    return Out().flag("hit", true).num("t", t).str();
}

std::string triangle_intersect(const Json &in) {   // Moeller-Trumbore
    V o = vec(in["origin"]), d = vec(in["direction"]), p0 = vec(in["p0"]);
    V e1 = vec(in["p1"]) - p0, e2 = vec(in["p2"]) - p0, pv = cross(d, e2);
    double det = dot(e1, pv);
    if (std::fabs(det) < 1e-12) return Out().flag("hit", false).str();
    V tv = o - p0, qv = cross(tv, e1);
    double u = dot(tv, pv) / det, v = dot(d, qv) / det, t = dot(e2, qv) / det;
    if (u < 0 || v < 0 || u + v > 1 || t <= 0) return Out().flag("hit", false).str();
    return Out().flag("hit", true).num("t", t).num("u", u).num("v", v).str();
}

std::string reflect(const Json &in) {
    V d = vec(in["d"]), n = vec(in["n"]);
    return Out().vec("r", d - n * (2 * dot(d, n))).str();
}

std::string refract(const Json &in) {
    V d = vec(in["d"]), n = vec(in["n"]);
    double c, rel, cos_t, cos_i = -dot(d, n);
    snell(cos_i, in["eta"].num, c, rel, cos_t);
    if (cos_t < 0) return Out().flag("tir", true).str();
    V nf = cos_i >= 0 ? n : n * -1;   // the normal on the side the ray comes from
    return Out().flag("tir", false).vec("t", d * (1 / rel) + nf * (c / rel - cos_t)).str();
}

std::string fresnel_exact(const Json &in) {
    double c, rel, cos_t;
    snell(in["cos_i"].num, in["eta"].num, c, rel, cos_t);
    if (rel == 1) return Out().num("R", 0).str();
    if (cos_t < 0) return Out().num("R", 1).str();
    double rs = (c - rel * cos_t) / (c + rel * cos_t), rp = (rel * c - cos_t) / (rel * c + cos_t);
    return Out().num("R", (rs * rs + rp * rp) / 2).str();
}

std::string fresnel_schlick(const Json &in) {
    double c, rel, cos_t, eta = in["eta"].num;
    snell(in["cos_i"].num, eta, c, rel, cos_t);
    if (cos_t < 0) return Out().num("R", 1).str();
    double r0 = (eta - 1) / (eta + 1);
    r0 *= r0;
    double cos = rel >= 1 ? c : cos_t;   // the angle on the less dense side
    return Out().num("R", r0 + (1 - r0) * std::pow(1 - cos, 5)).str();
}

std::string lambert(const Json &in) {
    double cos = std::fmax(dot(vec(in["n"]), vec(in["wi"])), 0.0);
    return Out().num("value", in["albedo"].num / PI * cos).str();
}

std::string lobe(const Json &in, bool blinn) {
    V n = vec(in["n"]), wi = vec(in["wi"]), wo = vec(in["wo"]);
    double p = in["exponent"].num;
    if (dot(n, wi) <= 0 || dot(n, wo) <= 0) return Out().num("value", 0).str();
    double cos, norm;
    if (blinn) {
        cos = dot(n, normalize(wi + wo));
        norm = (p + 2) * (p + 4) / (8 * PI * (std::pow(2.0, -p / 2) + p));
    } else {
        cos = dot(n * (2 * dot(n, wi)) - wi, wo);
        norm = (p + 2) / (2 * PI);
    }
    double spec = cos > 0 ? norm * std::pow(cos, p) : 0;
    return Out().num("value", in["kd"].num / PI + in["ks"].num * spec).str();
}

std::string point_light(const Json &in) {
    V to = vec(in["position"]) - vec(in["p"]);
    double r = std::sqrt(dot(to, to));
    return Out().vec("direction", to * (1 / r)).num("distance", r)
        .num("irradiance", in["intensity"].num / (r * r)).str();
}

std::string spot_falloff(const Json &in) {
    double theta = std::acos(std::fmax(-1.0, std::fmin(1.0, in["cos_theta"].num))) * 180 / PI;
    double cutoff = in["cutoff_angle"].num, beam = in["beam_width"].num;
    double f = theta >= cutoff ? 0 : theta <= beam ? 1 : (cutoff - theta) / (cutoff - beam);
    return Out().num("falloff", f).str();
}

std::string answer(const Json &req) {
    const std::string &name = req["formula"].str;
    const Json &in = req["inputs"];
    if (name == "sphere_intersect") return sphere_intersect(in);
    if (name == "triangle_intersect") return triangle_intersect(in);
    if (name == "reflect") return reflect(in);
    if (name == "refract") return refract(in);
    if (name == "fresnel_exact") return fresnel_exact(in);
    if (name == "fresnel_schlick") return fresnel_schlick(in);
    if (name == "lambert") return lambert(in);
    if (name == "phong") return lobe(in, false);
    if (name == "blinn_phong") return lobe(in, true);
    if (name == "point_light") return point_light(in);
    if (name == "spot_falloff") return spot_falloff(in);
    return "";   // not implemented here: fresnel_conductor, camera_ray, instance_normal
}

int main() {
    std::string line;
    while (std::getline(std::cin, line)) {
        Parser p{line};
        Json req = p.value();
        long id = (long) req["id"].num;
        std::string out = answer(req);
        if (out.empty())
            std::cout << "{\"id\": " << id << ", \"error\": \"not implemented\"}" << std::endl;
        else
            std::cout << "{\"id\": " << id << ", \"outputs\": " << out << "}" << std::endl;
    }
}
