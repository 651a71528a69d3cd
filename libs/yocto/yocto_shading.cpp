//
// Implementation of Yocto/Shading.
//

#include "yocto_shading.h"

#include "yocto_sampling.h"

#include <algorithm>
#include <cmath>

#include <yocto_hair/yocto_hair.h>

// -----------------------------------------------------------------------------
// SHADING CONTEXT
// -----------------------------------------------------------------------------
namespace yocto {

shading_context make_shading_context(
    const scene_data& scene, const hair_sampling_params& hair_sampling) {
  auto context          = shading_context{};
  context.hair_sampling = hair_sampling;
  for (auto& material : scene.materials)
    context.hair.push_back(make_hair_precomputed(material.hair));
  context.strands.resize(scene.shapes.size());
  for (auto& instance : scene.instances) {
    auto& shape    = scene.shapes[instance.shape];
    auto& material = scene.materials[instance.material];
    auto  hair     = material.type == material_type::hair && shape.triangles.empty();
    auto  strands  = hair && hair_material_varies(material.hair);
    auto  colors   = hair && !shape.colors.empty() && material.hair.has_color &&
                  !material.hair.has_sigma_a;
    context.hair_varies.push_back(strands || colors);
    if (strands && context.strands[instance.shape].strand.empty())
      context.strands[instance.shape] = make_fiber_strands(shape);
  }
  return context;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// MATERIAL POINTS
// -----------------------------------------------------------------------------
namespace yocto {

bool scatters_nothing(const material_point& point) {
  return point.type == material_type::matte && point.color == vec3f{0, 0, 0};
}

material_point eval_material_point(const scene_data& scene, const shading_context& context,
    int instance_id, int element, const vec2f& uv, float distance, const ray3f& ray) {
  auto& instance = scene.instances[instance_id];
  auto& material = scene.materials[instance.material];
  auto& shape    = scene.shapes[instance.shape];
  auto  point    = material_point{};
  point.hair_sampling = context.hair_sampling;
  point.type      = material.type;
  point.color     = material.color;
  point.roughness = material.roughness;
  point.ior       = material.ior;
  point.emission  = material.emission;
  auto texcoord   = vec2f{0, 0};
  if (!shape.triangles.empty()) {
    auto surface   = eval_surface_point(scene, instance, element, uv);
    point.position = surface.position;
    texcoord       = surface.texcoord;
    // Emission only from the front face; shading from either side.
    if (dot(surface.gnormal, -ray.d) < 0) point.emission = {0, 0, 0};
    point.normal  = dot(surface.normal, -ray.d) >= 0 ? surface.normal : -surface.normal;
    point.gnormal = surface.gnormal;
  } else {
    auto fiber = eval_fiber_point(scene, instance, element, uv.x, ray, distance);
    point.fiber    = true;
    point.position = fiber.position;
    point.axis     = fiber.axis;
    point.radius   = fiber.radius;
    point.tangent  = fiber.tangent;
    point.normal   = fiber.normal;
    if (material.type == material_type::hair) {
      // The material's own terms, unless this groom varies (the material of
      // this strand at this place: the shape's colour there, the strand's
      // variation; of its terms only those that vary computed again) or the
      // terms are made at every hit. With the outgoing direction, so that the
      // terms depending on it are computed once for the hit's hair calls.
      auto& sampling = context.hair_sampling;
      auto  terms    = &context.hair[instance.material];
      auto  local    = hair_precomputed{};
      if (context.hair_varies[instance_id]) {
        auto hair = material.hair;
        auto t    = uv.x;  // along the segment
        if (!shape.colors.empty() && hair.has_color && !hair.has_sigma_a) {
          auto ends  = segment_ends(shape, element);
          hair.color = shape.colors[ends.x] + (shape.colors[ends.y] - shape.colors[ends.x]) * t;
        }
        auto& strands = context.strands[instance.shape];
        if (!strands.strand.empty()) {
          auto u = strands.u[element].x + (strands.u[element].y - strands.u[element].x) * t;
          hair   = eval_hair_material_point(
              hair, strands.random[strands.strand[element]], std::clamp(u, 0.0f, 1.0f));
        }
        if (material.hair.random_roughness != 0 || sampling.per_hit) {
          local = make_hair_precomputed(hair, sampling.fast_pow);
        } else {
          local         = *terms;
          local.sigma_a = make_hair_absorption(hair);
        }
        terms = &local;
      } else if (sampling.per_hit) {
        local = make_hair_precomputed(material.hair, sampling.fast_pow);
        terms = &local;
      }
      point.hair = eval_hair_brdf(*terms, fiber.h, fiber.frame, -ray.d);
    }
  }
  if (material.color_tex >= 0)
    point.color *= eval_texture(scene.textures[material.color_tex], texcoord);
  if (material.emission_tex >= 0)
    point.emission *= eval_texture(scene.textures[material.emission_tex], texcoord);
  return point;
}

ray3f spawn_ray(const material_point& point, const vec3f& direction) {
  if (point.fiber)
    return spawn_fiber_ray(point.axis, point.tangent, point.radius, point.normal, direction);
  auto scale  = std::max(1.0f, max_component(abs(point.position)));
  auto offset = point.normal * (ray_eps * scale);
  auto o      = point.position + (dot(direction, point.normal) >= 0 ? offset : -offset);
  return {o, direction, 0, flt_max};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// BSDFS
// -----------------------------------------------------------------------------
namespace yocto {

// Fresnel reflectance of a dielectric interface (unpolarised).
static float fresnel_dielectric(float eta, float cos_w) {
  cos_w       = std::abs(cos_w);
  auto sin2_t = (1 - cos_w * cos_w) / (eta * eta);
  if (sin2_t >= 1) return 1;
  auto cos_t = safe_sqrt(1 - sin2_t);
  auto rs    = (cos_w - eta * cos_t) / (cos_w + eta * cos_t);
  auto rp    = (eta * cos_w - cos_t) / (eta * cos_w + cos_t);
  return (rs * rs + rp * rp) / 2;
}

// GGX distribution and Smith masking (Walter et al., Microfacet Models for
// Refraction through Rough Surfaces, EGSR 2007), alpha = roughness^2.
static float ggx_distribution(float alpha, float cos_h) {
  if (cos_h <= 0) return 0;
  auto a2 = alpha * alpha, c2 = cos_h * cos_h;
  return a2 / (pif * sqr(c2 * (a2 - 1) + 1));
}
static float ggx_smith_g1(float alpha, float cos_w) {
  auto c2 = cos_w * cos_w;
  return 2 / (1 + std::sqrt(1 + alpha * alpha * (1 - c2) / std::max(c2, 1e-12f)));
}
static float glossy_alpha(float roughness) { return std::max(sqr(roughness), 1e-3f); }

vec3f eval_bsdfcos(const material_point& point, const vec3f& outgoing, const vec3f& incoming) {
  if (point.type == material_type::hair) {
    return eval_hair_scattering(point.hair, outgoing, incoming);
  }
  auto cos_i = dot(point.normal, incoming), cos_o = dot(point.normal, outgoing);
  if (cos_i <= 0 || cos_o <= 0) return {0, 0, 0};
  if (point.type == material_type::matte) return point.color / pif * cos_i;
  // glossy: GGX coat over a Lambertian base
  auto alpha   = glossy_alpha(point.roughness);
  auto half    = normalize(incoming + outgoing);
  auto fresnel = fresnel_dielectric(point.ior, dot(half, outgoing));
  auto base    = 1 - fresnel_dielectric(point.ior, cos_o);
  auto specular = fresnel * ggx_distribution(alpha, dot(point.normal, half)) *
                  ggx_smith_g1(alpha, cos_o) * ggx_smith_g1(alpha, cos_i) / (4 * cos_o);
  return point.color / pif * base * cos_i + vec3f{specular, specular, specular};
}

float sample_bsdfcos_pdf(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming) {
  if (point.type == material_type::hair) {
    return sample_hair_scattering_pdf(point.hair, outgoing, incoming);
  }
  auto cos_i = dot(point.normal, incoming), cos_o = dot(point.normal, outgoing);
  if (cos_i <= 0 || cos_o <= 0) return 0;
  if (point.type == material_type::matte) return cos_i / pif;
  auto alpha     = glossy_alpha(point.roughness);
  auto half      = normalize(incoming + outgoing);
  auto specular  = fresnel_dielectric(point.ior, cos_o);
  auto pdf_half  = ggx_distribution(alpha, dot(point.normal, half)) * dot(point.normal, half);
  return specular * pdf_half / (4 * std::abs(dot(outgoing, half))) +
         (1 - specular) * cos_i / pif;
}

std::pair<vec3f, float> eval_bsdfcos_and_pdf(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming) {
  if (point.type == material_type::hair) {
    return eval_hair_scattering_and_pdf(point.hair, outgoing, incoming);
  }
  return {eval_bsdfcos(point, outgoing, incoming),
      sample_bsdfcos_pdf(point, outgoing, incoming)};
}

bool may_scatter(const material_point& point, const vec3f& outgoing, const vec3f& incoming) {
  return point.type == material_type::hair ||
         (dot(point.normal, incoming) > 0 && dot(point.normal, outgoing) > 0);
}

vec3f eval_albedo(const material_point& point, const vec3f& outgoing) {
  auto albedo = vec3f{0, 0, 0};
  if (point.type == material_type::hair) {
    albedo = eval_hair_albedo(point.hair, outgoing);
  } else if (point.type == material_type::matte) {
    albedo = point.color;
  } else {
    auto fresnel = fresnel_dielectric(point.ior, dot(point.normal, outgoing));
    albedo       = point.color * (1 - fresnel) + vec3f{fresnel, fresnel, fresnel};
  }
  return glm::clamp(albedo, 0.0f, 1.0f);
}

// `more` is used by hair with hair_sampling.four_numbers only (empty otherwise).
static vec3f sample_bsdfcos(const material_point& point, const vec3f& outgoing, float rnl,
    const vec2f& rn, const vec2f& more) {
  if (point.type == material_type::hair) {
    if (point.hair_sampling.four_numbers) {
      return sample_hair_scattering(point.hair, outgoing, vec4f{rn.x, rn.y, more.x, more.y});
    }
    return sample_hair_scattering(point.hair, outgoing, rn);
  }
  if (point.type == material_type::matte) return sample_hemisphere_cos(point.normal, rn);
  auto specular = fresnel_dielectric(point.ior, dot(point.normal, outgoing));
  if (rnl >= specular) return sample_hemisphere_cos(point.normal, rn);
  // GGX half vector: tan^2 theta = alpha^2 u / (1 - u).
  auto alpha = glossy_alpha(point.roughness);
  auto phi   = 2 * pif * rn.x;
  auto tan2  = alpha * alpha * rn.y / std::max(1 - rn.y, 1e-7f);
  auto cos_h = 1 / std::sqrt(1 + tan2), sin_h = safe_sqrt(1 - cos_h * cos_h);
  auto local = vec3f{sin_h * std::cos(phi), sin_h * std::sin(phi), cos_h};
  auto half  = normalize(basis_fromz(point.normal) * local);
  return reflect(outgoing, half);
}

std::array<vec3f, 4> eval_bsdfcos_lobes(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming) {
  if (point.type != material_type::hair) return {};
  return eval_hair_scattering_lobes(point.hair, outgoing, incoming);
}

bool bsdf_takes_more_numbers(const material_point& point) {
  return point.type == material_type::hair && point.hair_sampling.four_numbers;
}

bsdf_sample sample_bsdf(const material_point& point, const vec3f& outgoing, float rnl,
    const vec2f& rn, const vec2f& more, bool needs_pdf, const std::array<float, 4>* lobe_worth,
    float guided) {
  auto sample = bsdf_sample{};
  if (point.type == material_type::hair && !needs_pdf && !point.hair_sampling.mixture_weight) {
    // No pdf needed: the sampled lobe's own weight, no evaluation.
    auto four = vec4f{rn.x, rn.y, more.x, more.y};
    auto hair = hair_sample{};
    if (lobe_worth && point.hair_sampling.four_numbers)
      hair = sample_hair_scattering_weight(point.hair, outgoing, four, *lobe_worth, guided);
    else if (lobe_worth)
      hair = sample_hair_scattering_weight(point.hair, outgoing, rn, *lobe_worth, guided);
    else if (point.hair_sampling.four_numbers)
      hair = sample_hair_scattering_weight(point.hair, outgoing, four);
    else
      hair = sample_hair_scattering_weight(point.hair, outgoing, rn);
    if (hair.incoming == vec3f{0, 0, 0} || !isfinite(hair.incoming)) return {};
    if (hair.weight == vec3f{0, 0, 0}) return {};
    sample.incoming = hair.incoming;
    sample.weight   = hair.weight;
    sample.lobe     = hair.lobe;
    return sample;
  }
  auto incoming = sample_bsdfcos(point, outgoing, rnl, rn, more);
  if (incoming == vec3f{0, 0, 0} || !isfinite(incoming)) return {};
  auto [bsdfcos, pdf] = eval_bsdfcos_and_pdf(point, outgoing, incoming);
  if (!(pdf > 0) || bsdfcos == vec3f{0, 0, 0}) return {};
  sample.incoming = incoming;
  sample.bsdfcos  = bsdfcos;
  sample.pdf      = pdf;
  sample.weight   = bsdfcos / pdf;
  return sample;
}

}  // namespace yocto
